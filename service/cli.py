"""`pbdag`: serve the API, run workers, migrate, export the OpenAPI file (and the commands of
service/auth_cli.py, service/admin_cli.py and service/scenes_cli.py).

Exit codes: 0 done, 1 the command ran and found a problem, 2 a configuration or usage error (one
line on stderr), 3 `serve` could not listen on its port, 141 standard output closed early.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import sys
import threading
from importlib.metadata import PackageNotFoundError, entry_points, version
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

from pbdag_errors import PbdagError
from service.admin_cli import register as register_admin_commands
from service.auth_cli import register as register_token_commands
from service.cli_support import (
    load_settings,
    open_container,
    redacted,
    setting_help,
    settings_epilog,
    settings_problem,
)
from service.logs import configure_logging
from service.scenes_cli import register as register_scene_commands
from service.settings import Settings, SettingsError

if TYPE_CHECKING:
    from fastapi import FastAPI

    from service.bootstrap import Container
    from service.worker import Worker

OPENAPI_PATH = Path(__file__).resolve().parents[1] / "api_schema" / "openapi.json"


DISTRIBUTION = "pbdag"  # [project] name in pyproject.toml
DESCRIPTION = (
    "The long-term 3D scene-graph memory of a robot: serve its HTTP API, run workers, create or "
    "upgrade the database, manage API tokens, list, rename, delete, rebuild, repair and export "
    "scenes, collect old raw batches, move them between blob backends."
)
EPILOG = (
    "`pbdag COMMAND --help` lists a command's options. Every command that opens the database "
    "names it on stderr; all but `serve` and `migrate` stop (exit 2) when its SQLite file does "
    "not exist. A configuration error is one line naming the variable, exit 2."
)
STDOUT_CLOSED = 141  # 128 + SIGPIPE, what a shell reports for a command whose reader left


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `pbdag` command."""
    try:
        return run(build_parser().parse_args(argv))
    except BrokenPipeError:  # `pbdag gc --dry-run | head -1`: the reader left; nothing to say
        return stdout_closed()


def build_parser() -> argparse.ArgumentParser:
    """`pbdag` and every subcommand, the plugins' (`pbdag.commands` entry points) included."""
    parser = argparse.ArgumentParser(prog="pbdag", description=DESCRIPTION, epilog=EPILOG)
    parser.add_argument(
        "--version", action="version", version=f"pbdag {package_version()}", help="print it, exit"
    )
    commands = parser.add_subparsers(
        dest="command",
        required=True,
        metavar="COMMAND",
        help="`pbdag COMMAND --help` lists its options",
    )
    add_service_commands(commands)
    register_token_commands(commands)  # `pbdag token create|list|revoke`
    register_admin_commands(commands)  # `pbdag rebuild|requeue|repair|gc|export|blobs`
    register_scene_commands(commands)  # `pbdag scenes list|rename|delete`
    for entry_point in entry_points(group="pbdag.commands"):  # e.g. `pbdag eval`, from evaluation
        try:
            entry_point.load()(commands)
        except Exception as error:  # a broken plugin must not take the service's commands down
            print(f"pbdag: command {entry_point.name!r} unavailable: {error}", file=sys.stderr)
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the chosen command; a configuration error is one line on stderr and exit code 2."""
    try:
        code = int(args.handler(args))
        if sys.stdout is not None:  # None: started with stdout closed (`>&-`)
            sys.stdout.flush()  # here, where a closed pipe is caught, not at interpreter exit
        return code
    except SettingsError as error:  # settings that cannot work together: say which, start nothing
        print(f"pbdag: {error}", file=sys.stderr)
        return 2
    except ValidationError as error:  # Settings() read somewhere else than load_settings
        if error.title != Settings.__name__:
            raise
        print(f"pbdag: {settings_problem(error)}", file=sys.stderr)
        return 2


def stdout_closed() -> int:
    """Point stdout at /dev/null (Python flushes it once more on exit) and return 141."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # a stdout without a descriptor (a test's capture)
        pass
    finally:
        os.close(devnull)
    return STDOUT_CLOSED


def package_version() -> str:
    """The installed distribution's version (`unknown` when run from an uninstalled tree)."""
    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:
        return "unknown"


def add_service_commands(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`serve`, `worker`, `migrate` and `openapi`."""
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
        help="API only, no worker in this process; run `pbdag worker` separately "
        "(env PBDAG_RUN_WORKER=false; default: a worker runs in the API process)",
    )
    add_logging_options(serve)
    serve.set_defaults(handler=_serve)

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
    worker.set_defaults(handler=_worker)

    migrate = commands.add_parser(
        "migrate", help="create the database (and its folder) or upgrade its schema"
    )
    migrate.set_defaults(handler=_migrate)

    openapi = commands.add_parser("openapi", help="write the OpenAPI document")
    openapi.add_argument(
        "--out",
        type=Path,
        default=OPENAPI_PATH,
        help=f"the file to write (default: {OPENAPI_PATH.relative_to(OPENAPI_PATH.parents[1])})",
    )
    openapi.set_defaults(handler=_openapi)


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
    settings = load_settings()
    for argument, field in fields.items():
        value = getattr(args, argument, None)
        if value is not None:
            setattr(settings, field, value)
    configure_logging(settings.log_format, settings.log_level)
    return settings


def _serve(args: argparse.Namespace) -> int:
    from service.app import create_app
    from service.auth_cli import access_summary, serve_refusal
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
    container = open_container(settings, create=True)
    refusal = serve_refusal(settings.host, container.engine)  # before binding anything
    if refusal is not None:
        print(refusal, file=sys.stderr)
        return 2
    try:
        listener = bound_socket(settings.host, settings.port)  # before saying where the API is
    except OSError as error:
        print(
            f"pbdag serve: cannot listen on {settings.host}:{settings.port}: "
            f"{error.strerror or error}; choose another with --port or PBDAG_PORT, "
            "or stop the process that holds it",
            file=sys.stderr,
        )
        container.engine.dispose()
        return 3
    print(
        f"pbdag: raw batches in {blob_location(container.blobs)} "
        f"(PBDAG_BLOB_BACKEND={settings.blob_backend})"
    )
    print(f"pbdag: API on http://{settings.host}:{settings.port} ({pages(settings)})", flush=True)
    print(f"pbdag: allowed Host names {', '.join(settings.allowed_hosts)} (PBDAG_ALLOWED_HOSTS)")
    print(access_summary(container.engine, settings.allow_anonymous_local), flush=True)
    return _run_server(create_app(container, run_worker=settings.run_worker), settings, listener)


def pages(settings: Settings) -> str:
    """Where the docs and metrics are, and whether a browser may open the docs (it sends no
    token: only anonymous local access lets it in)."""
    if settings.allow_anonymous_local:
        return "docs at /docs, metrics at /metrics"
    return (
        "docs at /docs with a read token, which a browser does not send: "
        "PBDAG_ALLOW_ANONYMOUS_LOCAL=true opens them locally, or read api_schema/openapi.json; "
        "metrics at /metrics"
    )


def bound_socket(host: str, port: int) -> socket.socket:
    """A TCP socket bound to host:port as uvicorn binds one (OSError when the port is taken)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    sock.set_inheritable(True)
    return sock


def _run_server(app: FastAPI, settings: Settings, listener: socket.socket) -> int:
    import uvicorn

    # log_config=None: uvicorn's records go through the handler configured above (text or JSON).
    # X-Forwarded-For names the client only when a trusted proxy sent it (uvicorn's own default
    # trusts it from loopback); with no proxy listed, uvicorn does not read it at all.
    config = uvicorn.Config(
        app,
        host=settings.host,
        port=settings.port,
        log_level="warning",
        log_config=None,
        proxy_headers=bool(settings.trusted_proxies),
        forwarded_allow_ips=settings.trusted_proxies,
    )
    server = uvicorn.Server(config)
    try:
        server.run(sockets=[listener])
    finally:
        listener.close()
    return 0 if server.started else 3  # as uvicorn.run: 3 when the server did not start


def _worker(args: argparse.Namespace) -> int:
    from prometheus_client import start_http_server

    from service.worker import Worker

    settings = settings_with(
        args, metrics_port="metrics_port", log_format="log_format", log_level="log_level"
    )
    container = open_container(settings)
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
    from service.cli_support import migrated

    configure_logging()
    url, before, after = migrated(load_settings())
    if before is None:
        print(f"pbdag: migrated an empty database {redacted(url)} to revision {after}")
    elif before != after:
        print(f"pbdag: migrated {redacted(url)} from revision {before} to {after}")
    else:
        print(f"pbdag: schema of {redacted(url)} is up to date (revision {after})")
    return 0


def _openapi(args: argparse.Namespace) -> int:
    configure_logging()
    from service.app import create_app
    from service.bootstrap import build_container
    from service.store.blobs import MemoryBlobStore
    from service.store.engine import make_engine

    container = build_container(
        load_settings(), blobs=MemoryBlobStore(), engine=make_engine("sqlite://")
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


if __name__ == "__main__":
    sys.exit(main())
