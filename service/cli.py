"""`pbdag`: serve the API, run workers, migrate, export the OpenAPI file (and the commands of
service/auth_cli.py and service/admin_cli.py)."""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from importlib.metadata import entry_points
from pathlib import Path

from service.admin_cli import register as register_admin_commands
from service.auth_cli import register as register_token_commands
from service.settings import Settings

OPENAPI_PATH = Path(__file__).resolve().parents[1] / "api_schema" / "openapi.json"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `pbdag` command."""
    parser = argparse.ArgumentParser(prog="pbdag", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    serve = commands.add_parser(
        "serve", help="run the HTTP API (with an in-process worker by default)"
    )
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument(
        "--no-worker", action="store_true", help="API only; run `pbdag worker` separately"
    )

    worker = commands.add_parser(
        "worker", help="process queued batches (several may share one PostgreSQL)"
    )
    worker.add_argument("--drain", action="store_true", help="exit once the queue is empty")

    commands.add_parser("migrate", help="create or upgrade the database schema")

    openapi = commands.add_parser("openapi", help="write the OpenAPI document")
    openapi.add_argument("--out", type=Path, default=OPENAPI_PATH)
    register_token_commands(commands)  # `pbdag token create|list|revoke`
    register_admin_commands(commands)  # `pbdag rebuild|requeue|repair`

    for entry_point in entry_points(group="pbdag.commands"):  # e.g. `pbdag eval`, from evaluation
        try:
            entry_point.load()(commands)
        except Exception as error:  # a broken plugin must not take the service's commands down
            print(f"pbdag: command {entry_point.name!r} unavailable: {error}", file=sys.stderr)
    args = parser.parse_args(argv)
    if hasattr(args, "handler"):
        return int(args.handler(args))
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    logging.getLogger("alembic").setLevel(logging.WARNING)
    handlers = {
        "serve": _serve,
        "worker": _worker,
        "migrate": _migrate,
        "openapi": _openapi,
    }
    return handlers[args.command](args)


def _serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.app import create_app
    from service.auth_cli import access_summary, serve_refusal
    from service.bootstrap import build_container
    from service.security import hosts_when_serving

    settings = Settings()
    settings.allowed_hosts = hosts_when_serving(settings.allowed_hosts, args.host)
    container = build_container(settings)
    refusal = serve_refusal(args.host, container.engine)  # before binding anything
    if refusal is not None:
        print(refusal, file=sys.stderr)
        return 2
    print(
        f"pbdag: database {_redacted(settings.resolved_database_url())}, data in {settings.data_dir.resolve()}"
    )
    print(f"pbdag: API on http://{args.host}:{args.port} (docs at /docs)", flush=True)
    print(f"pbdag: allowed Host names {', '.join(settings.allowed_hosts)} (PBDAG_ALLOWED_HOSTS)")
    print(access_summary(container.engine, settings.allow_anonymous_local), flush=True)
    app = create_app(container, run_worker=not args.no_worker)
    uvicorn.run(app, host=args.host, port=args.port, log_level="warning")
    return 0


def _worker(args: argparse.Namespace) -> int:
    from service.bootstrap import build_container
    from service.worker import Worker

    container = build_container()
    worker = Worker(container)
    if args.drain:
        processed = worker.drain()
        print(f"pbdag worker {worker.name}: processed {processed} batches")
        return 0
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    worker.run(stop)
    return 0


def _migrate(_args: argparse.Namespace) -> int:
    from service.bootstrap import build_container

    container = build_container()
    print(f"pbdag: schema of {_redacted(container.settings.resolved_database_url())} is up to date")
    return 0


def _openapi(args: argparse.Namespace) -> int:
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


def _redacted(url: str) -> str:
    """The URL without its password."""
    from sqlalchemy import make_url

    return make_url(url).render_as_string(hide_password=True)


if __name__ == "__main__":
    sys.exit(main())
