"""`pbdag`: serve the API, run workers, migrate, export the OpenAPI file (and the commands of
service/auth_cli.py and service/admin_cli.py)."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import textwrap
import threading
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING

from pbdag_errors import PbdagError
from service.admin_cli import register as register_admin_commands
from service.auth_cli import register as register_token_commands
from service.logs import configure_logging
from service.settings import Settings, SettingsError

if TYPE_CHECKING:
    from service.bootstrap import Container
    from service.worker import Worker

OPENAPI_PATH = Path(__file__).resolve().parents[1] / "api_schema" / "openapi.json"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `pbdag` command."""
    parser = argparse.ArgumentParser(prog="pbdag", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    serve = commands.add_parser(
        "serve",
        help="run the HTTP API (with an in-process worker by default)",
        description="Run the HTTP API (with an in-process worker by default). Every option "
        "falls back to its environment variable, then to its default.",
        epilog=settings_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    serve.add_argument("--host", help=setting_help("host", "address to listen on"))
    serve.add_argument("--port", type=int, help=setting_help("port", "port to listen on"))
    serve.add_argument(
        "--no-worker",
        dest="run_worker",
        action="store_const",
        const=False,
        help=setting_help("run_worker", "API only; run `pbdag worker` separately"),
    )
    add_logging_options(serve)

    worker = commands.add_parser(
        "worker",
        help="process queued batches (several may share one PostgreSQL)",
        epilog=settings_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    worker.add_argument("--drain", action="store_true", help="exit once the queue is empty")
    worker.add_argument(
        "--metrics-port",
        type=int,
        help=setting_help(
            "metrics_port", "serve this worker's Prometheus metrics on 127.0.0.1:PORT"
        ),
    )
    add_logging_options(worker)

    commands.add_parser("migrate", help="create or upgrade the database schema")

    openapi = commands.add_parser("openapi", help="write the OpenAPI document")
    openapi.add_argument("--out", type=Path, default=OPENAPI_PATH)
    register_token_commands(commands)  # `pbdag token create|list|revoke`
    register_admin_commands(commands)  # `pbdag rebuild|requeue|repair|gc|export|blobs`

    for entry_point in entry_points(group="pbdag.commands"):  # e.g. `pbdag eval`, from evaluation
        try:
            entry_point.load()(commands)
        except Exception as error:  # a broken plugin must not take the service's commands down
            print(f"pbdag: command {entry_point.name!r} unavailable: {error}", file=sys.stderr)
    args = parser.parse_args(argv)
    handlers = {
        "serve": _serve,
        "worker": _worker,
        "migrate": _migrate,
        "openapi": _openapi,
    }
    try:
        if hasattr(args, "handler"):
            return int(args.handler(args))
        return handlers[args.command](args)
    except SettingsError as error:  # settings that cannot work together: say which, start nothing
        print(f"pbdag: {error}", file=sys.stderr)
        return 2


def env_name(field: str) -> str:
    """The environment variable of a setting."""
    return f"PBDAG_{field.upper()}"


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


def add_logging_options(command: argparse.ArgumentParser) -> None:
    """--log-format and --log-level."""
    command.add_argument(
        "--log-format",
        choices=("text", "json"),
        help=setting_help("log_format", "text lines, or one JSON object per line"),
    )
    command.add_argument(
        "--log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help=setting_help("log_level", "least severe level logged"),
    )


def settings_with(args: argparse.Namespace, **fields: str) -> Settings:
    """The settings, with the options given on the command line (argument -> setting)."""
    settings = Settings()
    for argument, field in fields.items():
        value = getattr(args, argument, None)
        if value is not None:
            setattr(settings, field, value)
    configure_logging(settings.log_format, settings.log_level)
    return settings


def _serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.app import create_app
    from service.auth_cli import access_summary, serve_refusal
    from service.bootstrap import build_container
    from service.security import hosts_when_serving

    settings = settings_with(
        args,
        host="host",
        port="port",
        run_worker="run_worker",
        log_format="log_format",
        log_level="log_level",
    )
    settings.allowed_hosts = hosts_when_serving(settings.allowed_hosts, settings.host)
    container = build_container(settings)
    refusal = serve_refusal(settings.host, container.engine)  # before binding anything
    if refusal is not None:
        print(refusal, file=sys.stderr)
        return 2
    print(
        f"pbdag: database {_redacted(settings.resolved_database_url())}, "
        f"raw batches in {blob_location(container.blobs)} "
        f"(PBDAG_BLOB_BACKEND={settings.blob_backend})"
    )
    print(
        f"pbdag: API on http://{settings.host}:{settings.port} (docs at /docs, metrics at /metrics)",
        flush=True,
    )
    print(f"pbdag: allowed Host names {', '.join(settings.allowed_hosts)} (PBDAG_ALLOWED_HOSTS)")
    print(access_summary(container.engine, settings.allow_anonymous_local), flush=True)
    app = create_app(container, run_worker=settings.run_worker)
    # log_config=None: uvicorn's records go through the handler configured above (text or JSON).
    # X-Forwarded-For names the client only when a trusted proxy sent it (uvicorn's own default
    # trusts it from loopback); with no proxy listed, uvicorn does not read it at all.
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        log_level="warning",
        log_config=None,
        proxy_headers=bool(settings.trusted_proxies),
        forwarded_allow_ips=settings.trusted_proxies,
    )
    return 0


def _worker(args: argparse.Namespace) -> int:
    from prometheus_client import start_http_server

    from service.bootstrap import build_container
    from service.worker import Worker

    settings = settings_with(
        args, metrics_port="metrics_port", log_format="log_format", log_level="log_level"
    )
    container = build_container(settings)
    if settings.metrics_port:
        start_http_server(settings.metrics_port, "127.0.0.1", container.metrics.registry)
        print(f"pbdag worker: metrics on http://127.0.0.1:{settings.metrics_port}/metrics")
    worker = Worker(container)
    if args.drain:
        try:
            processed = worker.drain()
            print(f"pbdag worker {worker.name}: processed {processed} batches")
            return _left_undone(container, worker)
        except PbdagError as error:  # the queue itself failed (a lost or unwritable database)
            print(f"pbdag worker: the queue failed: {error.detail}", file=sys.stderr)
            return 1
        finally:
            container.engine.dispose()
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    worker.run(stop)
    return 0


UNDONE = ("queued", "failed", "running")  # failed: waiting for its retry


def _left_undone(container: Container, worker: Worker) -> int:
    """0 when the queue holds no batch still to be done, else 1 naming what is left and why."""
    try:
        counts = container.queue.counts()
    except PbdagError as error:
        print(f"pbdag worker: cannot read the queue: {error.detail}", file=sys.stderr)
        return 1
    left = {status: counts.get(status, 0) for status in UNDONE if counts.get(status, 0)}
    if not left and not worker.unrecorded:
        return 0
    listed = ", ".join(f"{count} {status}" for status, count in left.items()) or "none queued"
    print(f"pbdag worker: work left undone ({listed})", file=sys.stderr, end="")
    if worker.unrecorded:
        print(f"; {worker.unrecorded} failures not recorded", file=sys.stderr, end="")
    reason = worker.health.problem or "batches waiting for a retry or held by another worker"
    print(f": {reason}", file=sys.stderr)
    return 1


def _migrate(_args: argparse.Namespace) -> int:
    from service.bootstrap import build_container

    configure_logging()
    container = build_container()
    print(f"pbdag: schema of {_redacted(container.settings.resolved_database_url())} is up to date")
    return 0


def _openapi(args: argparse.Namespace) -> int:
    configure_logging()
    from service.app import create_app
    from service.bootstrap import build_container
    from service.store.blobs import MemoryBlobStore
    from service.store.engine import make_engine

    container = build_container(
        Settings(), blobs=MemoryBlobStore(), engine=make_engine("sqlite://")
    )
    document = create_app(container).openapi()
    args.out.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
    print(f"wrote {args.out}")
    return 0


def blob_location(blobs: object) -> str:
    """Where a blob store keeps the raw batches, for the startup line."""
    from service.store.blobs import FileBlobStore, PgBlobStore

    if isinstance(blobs, PgBlobStore):
        return "the database"
    if isinstance(blobs, FileBlobStore):
        return f"the folder {blobs.root.resolve()}"
    return type(blobs).__name__


def _redacted(url: str) -> str:
    """The URL without its password."""
    from sqlalchemy import make_url

    return make_url(url).render_as_string(hide_password=True)


if __name__ == "__main__":
    sys.exit(main())
