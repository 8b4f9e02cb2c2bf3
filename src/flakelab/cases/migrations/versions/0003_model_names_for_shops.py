"""Model names long enough for a shop's own model.

A model adapted to one shop is registered as 'INSTRUMENT @ SHOP' (instrument up to 60
characters, shop up to 120): 183 characters, where the name column held 80.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-29
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # batch: SQLite alters a column's type by copying the table (its rows and index kept)
    with op.batch_alter_table("models") as batch:
        batch.alter_column(
            "name", type_=sa.String(200), existing_type=sa.String(80), existing_nullable=False
        )


def downgrade() -> None:
    with op.batch_alter_table("models") as batch:
        batch.alter_column(
            "name", type_=sa.String(80), existing_type=sa.String(200), existing_nullable=False
        )
