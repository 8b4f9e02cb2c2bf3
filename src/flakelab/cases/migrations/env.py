"""Alembic environment: runs on the connection flakelab hands over (or the configured URL)."""

from alembic import context
from sqlalchemy import engine_from_config, pool

from flakelab.cases.schema import Base, render_for_migration

config = context.config
target_metadata = Base.metadata


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        context.configure(connection=connection, target_metadata=target_metadata,
                          render_as_batch=True, render_item=render_for_migration)  # fmt: skip
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = engine_from_config(config.get_section(config.config_ini_section, {}),
                                prefix="sqlalchemy.", poolclass=pool.NullPool)  # fmt: skip
    with engine.connect() as connection:
        context.configure(connection=connection, target_metadata=target_metadata,
                          render_as_batch=True, render_item=render_for_migration)  # fmt: skip
        with context.begin_transaction():
            context.run_migrations()


if context.is_offline_mode():
    context.configure(url=config.get_main_option("sqlalchemy.url"),
                      target_metadata=target_metadata, literal_binds=True,
                      render_item=render_for_migration)  # fmt: skip
    with context.begin_transaction():
        context.run_migrations()
else:
    run_migrations_online()
