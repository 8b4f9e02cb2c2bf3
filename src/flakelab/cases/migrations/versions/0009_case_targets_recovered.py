"""Whether each case's target was known by its colour alone.

An instrument that exports L*a*b* alone, or a car maker's standard given as its L*a*b*, gives
a target whose spectra flakelab recovers from its colour in D65/10: one metamer of many. A
case keeps such a target, flagged, since its target is read for its colour there alone; the
spray-out, from which the learned model learns, must still be measured. Cases stored before
were measured (false).

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-04
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.add_column(
            sa.Column("target_recovered", sa.Boolean, nullable=False, server_default=sa.false())
        )


def downgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        batch.drop_column("target_recovered")
