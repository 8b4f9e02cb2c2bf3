"""One row per version of a registered model.

Registrations that ran at once on a shared database could read the same last version and
both store the next, and both promote themselves. A version number is now the name's alone
(the registry judges again when it finds its number taken). Versions already stored twice
keep their rows: the later ones, in the order stored, take the name's next free numbers; of
a name's promoted versions, the last stored stays promoted and the others are retired.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-02
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

_models = sa.table(
    "models",
    sa.column("id", sa.Integer),
    sa.column("name", sa.String),
    sa.column("version", sa.Integer),
    sa.column("status", sa.String),
)


def upgrade() -> None:
    bind = op.get_bind()
    rows = bind.execute(
        sa.select(_models.c.id, _models.c.name, _models.c.version, _models.c.status).order_by(
            _models.c.id
        )
    ).all()
    last = {}
    for _, name, version, _ in rows:
        last[name] = max(last.get(name, 0), version)
    taken, promoted = set(), {}
    for id_, name, version, status in rows:
        if (name, version) in taken:
            last[name] += 1
            bind.execute(_models.update().where(_models.c.id == id_).values(version=last[name]))
        taken.add((name, version))
        if status == "promoted":
            if name in promoted:
                bind.execute(
                    _models.update().where(_models.c.id == promoted[name]).values(status="retired")
                )
            promoted[name] = id_
    # batch: SQLite adds a constraint by copying the table (its rows and index kept)
    with op.batch_alter_table("models") as batch:
        batch.create_unique_constraint("uq_models_name_version", ["name", "version"])


def downgrade() -> None:
    with op.batch_alter_table("models") as batch:
        batch.drop_constraint("uq_models_name_version", type_="unique")
