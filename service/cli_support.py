"""What every `pbdag` command shares: settings read with one-line errors, the database opened
(and named) once, help texts of the options that override a setting.

A configuration mistake is one line on stderr naming the environment variable, the value given
(a URL without its password, a secret not at all) and the fix; the command exits 2.
"""

from __future__ import annotations

import logging
import re
import sys
import textwrap
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from service.settings import Settings, SettingsError

if TYPE_CHECKING:
    import sqlalchemy as sa

    from service.bootstrap import Container

SECRET_FIELDS = ("database_password",)  # never echoed back, not even wrong
URL_PASSWORD = re.compile(r"(://[^:/@]*:)[^@/]*@")  # user:PASSWORD@ in text that is no URL


def env_name(field: str) -> str:
    """The environment variable of a setting (`blob_backend` -> `PBDAG_BLOB_BACKEND`)."""
    prefix = str(Settings.model_config.get("env_prefix", ""))
    return f"{prefix}{field}".upper()


def shown_default(field: str) -> str:
    """A setting's default as a person would type it."""
    info = Settings.model_fields[field]
    value = info.get_default(call_default_factory=True)
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list):
        return ",".join(str(item) for item in value) or "empty"
    return str(value)


def setting_help(field: str, text: str) -> str:
    """Help of an option that overrides a setting: its default and its variable."""
    return f"{text} (default: {shown_default(field)}; env {env_name(field)})"


def settings_epilog() -> str:
    """Every setting: its variable, default and meaning (from service/settings.py)."""
    lines = ["environment (also a file /run/secrets/<variable in lower case>):"]
    for field, info in Settings.model_fields.items():
        lines.append(f"  {env_name(field)}={shown_default(field)}")
        for line in textwrap.wrap(info.description or "", 72):
            lines.append(f"      {line}")
    return "\n".join(lines)


def redacted(url: str) -> str:
    """`url` without its password (`user:***@host`), as SQLAlchemy renders it; text SQLAlchemy
    cannot parse as a URL (a malformed setting) with any `user:password@` part masked."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        return make_url(url).render_as_string(hide_password=True)
    except ArgumentError:
        return URL_PASSWORD.sub(r"\1***@", url)


def shown_value(field: str, value: Any) -> str:
    """A setting's value as a message may show it: secrets hidden, URLs without a password."""
    if field in SECRET_FIELDS:
        return "(hidden)"
    return repr(redacted(value) if isinstance(value, str) else value)


def settings_problem(error: ValidationError) -> str:
    """One line for every invalid setting of `error`: variable, value, what is wrong, the fix."""
    problems = []
    for item in error.errors(include_url=False):
        field = str(item["loc"][0]) if item["loc"] else ""
        if field not in Settings.model_fields:
            problems.append(str(item["msg"]))
            continue
        message = str(item["msg"])
        message = message[0].lower() + message[1:] if message else "invalid"
        problems.append(
            f"{env_name(field)}={shown_value(field, item.get('input'))}: {message}; set "
            f"{env_name(field)} to a valid value or unset it (default: {shown_default(field)})"
        )
    return "; ".join(problems)


def load_settings(**overrides: Any) -> Settings:
    """The settings from the environment (then `overrides`); SettingsError in one line."""
    try:
        settings = Settings()
        return settings.model_copy(update=overrides) if overrides else settings
    except ValidationError as error:
        raise SettingsError(settings_problem(error)) from None


def sqlite_file(url: str) -> Path | None:
    """The file of an SQLite URL (None for another database or an in-memory one)."""
    from sqlalchemy import make_url

    parsed = make_url(url)
    if not parsed.drivername.startswith("sqlite") or parsed.database in (None, "", ":memory:"):
        return None
    return Path(parsed.database)


def open_container(settings: Settings | None = None, *, create: bool = False) -> Container:
    """The service's parts on the configured database, named once on stderr.

    A command that may not create the database (`create` False: all but `serve` and `migrate`)
    refuses a missing SQLite file instead of starting an empty memory in the wrong directory.
    A URL SQLAlchemy cannot use, or a server that does not answer, is one SettingsError line.
    """
    settings = settings or load_settings()
    url = database_url(settings)
    path = sqlite_file(url)
    if path is not None and not create and not path.exists():
        raise SettingsError(missing_database(settings, path))
    announce(settings, url)
    return opened(settings, url)


def announce(settings: Settings, url: str) -> None:
    """`pbdag: database URL` on stderr; a JSON log record instead when the command logs JSON
    (`serve`, `worker` with --log-format json), so that stderr stays one JSON object a line."""
    from service.logs import StderrHandler

    if settings.log_format == "json" and any(
        isinstance(handler, StderrHandler) for handler in logging.getLogger().handlers
    ):
        logging.getLogger("pbdag.cli").info("database %s", redacted(url))
        return
    print(f"pbdag: database {redacted(url)}", file=sys.stderr, flush=True)


def database_url(settings: Settings) -> str:
    """The resolved database URL, or SettingsError when SQLAlchemy cannot even parse it."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import ArgumentError

    url = settings.resolved_database_url()
    try:
        make_url(url)
    except ArgumentError:
        raise SettingsError(
            f"PBDAG_DATABASE_URL={redacted(url)!r} is not a database URL; set it to "
            "postgresql+psycopg://USER@HOST:5432/DATABASE or sqlite:////absolute/path/pbdag.db"
        ) from None
    return url


def missing_database(settings: Settings, path: Path) -> str:
    """Why a command stops on an SQLite file that does not exist, and how to point at the right one."""
    where = (
        "named by PBDAG_DATABASE_URL"
        if settings.database_url
        else f"PBDAG_DATABASE_URL is unset, so the default under PBDAG_DATA_DIR={settings.data_dir}"
    )
    return (
        f"no database file {path} ({where}); run from the directory that holds data/, set "
        "PBDAG_DATABASE_URL=sqlite:////path/to/pbdag.db or PBDAG_DATA_DIR, "
        "or create a new one with `pbdag migrate`"
    )


def opened(settings: Settings, url: str) -> Container:
    """build_container (schema migrated), the database's failures as one SettingsError line."""
    from service.bootstrap import build_container

    with database_errors(settings, url):
        return build_container(settings)


def migrated(settings: Settings) -> tuple[str, str | None, str | None]:
    """Create or upgrade the schema (`pbdag migrate`): the URL, the revision before and after."""
    from service.bootstrap import blob_store
    from service.store.engine import make_engine, migrate

    url = database_url(settings)
    announce(settings, url)
    with database_errors(settings, url):
        engine = make_engine(url)
        try:
            blob_store(settings, engine)  # a backend the database cannot hold stops here
            before = schema_revision(engine)
            migrate(engine)
            return url, before, schema_revision(engine)
        finally:
            engine.dispose()


def schema_revision(engine: sa.Engine) -> str | None:
    """The database's Alembic revision (None: no schema yet)."""
    from alembic.runtime.migration import MigrationContext

    with engine.connect() as connection:
        return MigrationContext.configure(connection).get_current_revision()


@contextmanager
def database_errors(settings: Settings, url: str) -> Iterator[None]:
    """A URL without a driver, or a database that cannot be opened, as one SettingsError line."""
    from sqlalchemy.exc import DBAPIError, NoSuchModuleError

    from service.store.errors import StoreUnavailable

    given = (
        f"PBDAG_DATABASE_URL={redacted(url)!r}"
        if settings.database_url
        else f"the database {redacted(url)} (PBDAG_DATABASE_URL unset)"
    )
    try:
        yield
    except (NoSuchModuleError, ImportError) as error:
        raise SettingsError(
            f"{given}: no driver for it ({driver_reason(error)}); use "
            "postgresql+psycopg://USER@HOST:5432/DATABASE or sqlite:////absolute/path/pbdag.db"
        ) from None
    except (StoreUnavailable, DBAPIError) as error:
        fix = (
            "check the file and its folder's permissions, or run `pbdag migrate`"
            if url.startswith("sqlite")
            else "check the host, port, database name and credentials"
        )
        raise SettingsError(
            f"{given}: the database cannot be opened: {driver_reason(error)}; {fix}"
        ) from None


def driver_reason(error: BaseException) -> str:
    """The driver's own reason, on one line: the first line of the innermost cause."""
    while error.__cause__ is not None:
        error = error.__cause__
    orig = getattr(error, "orig", None)  # a SQLAlchemy DBAPIError wraps the driver's
    if isinstance(orig, BaseException):
        error = orig
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return " ".join(lines[0].split()) if lines else type(error).__name__
