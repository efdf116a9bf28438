"""Alembic environment: the service's one MetaData, on the connection the caller hands in."""

from __future__ import annotations

from alembic import context

from service.store.engine import make_engine
from service.store.tables import metadata

target_metadata = metadata


def run_migrations() -> None:
    """Online migrations on `config.attributes["connection"]`, or on the configured URL."""
    connection = context.config.attributes.get("connection")
    if connection is not None:
        # One transaction around every pending migration: on SQLite (whose DDL alembic treats as
        # non-transactional, committing after each revision) the version read and all upgrades
        # then happen under one BEGIN IMMEDIATE, so concurrent `pbdag migrate`s cannot interleave.
        context.configure(
            connection=connection, target_metadata=target_metadata, transactional_ddl=True
        )
        with context.begin_transaction():
            context.run_migrations()
        return
    url = context.config.get_main_option("sqlalchemy.url")
    if not url:
        from service.settings import Settings

        url = Settings().resolved_database_url()
    engine = make_engine(url)
    with engine.connect() as connection:
        context.configure(connection=connection, target_metadata=target_metadata)
        with context.begin_transaction():
            context.run_migrations()


if context.is_offline_mode():
    raise SystemExit("offline migrations are not supported: run `pbdag migrate`")
run_migrations()
