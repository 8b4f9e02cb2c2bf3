"""Whether each case's target and spray-out were known by their colour alone.

An instrument that exports L*a*b* alone (a BYK-mac i), or a car maker's standard given as its
L*a*b*, gives readings whose spectra flakelab recovers from their colour in D65/10: one
metamer of many. A case keeps such readings, flagged, since they are read for their colour
there (its outcome, the nearest cases, a shop's habits); no model learns from a spray-out
known so. Cases stored before were measured (false).

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

COLUMNS = ("target_recovered", "sprayout_recovered")


def upgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        for name in COLUMNS:
            batch.add_column(sa.Column(name, sa.Boolean, nullable=False, server_default=sa.false()))


def downgrade() -> None:
    with op.batch_alter_table("cases") as batch:
        for name in reversed(COLUMNS):
            batch.drop_column(name)
