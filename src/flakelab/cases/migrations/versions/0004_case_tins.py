"""The tins a case's recipe was poured from.

A shop that reads its tins (``flakelab lots``) knows how strong each one it poured was and
its shade; a case keeps them, toner → lot, strength and shade, so that a model is judged
(and may learn) with what the shop knew. Cases stored before have none (NULL).

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-01
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.add_column(sa.Column("tins", sa.JSON, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.drop_column("tins")
