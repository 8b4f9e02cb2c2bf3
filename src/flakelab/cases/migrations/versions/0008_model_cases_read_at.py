"""When each registered version's training read its cases.

A shop retrains on a schedule (``flakelab train --when-new N``) once N cases have been stored
since the newest version read its own; a version registered before, or from a file trained
elsewhere, has none (NULL) and counts from its registration.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-03
"""

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("models") as batch:
        batch.add_column(sa.Column("cases_read_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("models") as batch:
        batch.drop_column("cases_read_at")
