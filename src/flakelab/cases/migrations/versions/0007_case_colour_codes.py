"""The car maker's colour code of each case.

A colorist starts from the code on the car's plate ('Toyota 1G3', 'LY9B'): the shop's
recipes for that code are the first place to look, and its cases are listed, searched and
exported by it. Cases stored before have none (an empty text).

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-03
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.add_column(sa.Column("colour_code", sa.String(40), nullable=False, server_default=""))


def downgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.drop_column("colour_code")
