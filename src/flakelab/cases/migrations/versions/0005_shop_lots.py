"""The shops' toner tins.

A shop that reads its tins (``flakelab lots calibrate``) keeps them in the database beside its
cases and habits, where every workplace of the shop finds them: each version of the toner-lot
document, numbered per shop; a version clashes with another stored from the same one.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-02
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "shop_lots",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("shop", sa.String(120), nullable=False),
        sa.Column("version", sa.Integer, nullable=False),
        sa.Column("document", sa.JSON, nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.UniqueConstraint("shop", "version", name="uq_shop_lots_shop_version"),
    )
    op.create_index("ix_shop_lots_shop", "shop_lots", ["shop"])


def downgrade() -> None:
    op.drop_table("shop_lots")
