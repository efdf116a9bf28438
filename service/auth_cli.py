"""`pbdag token create|list|revoke`, and the check that keeps `pbdag serve` off the LAN without tokens.

service.auth (FastAPI, SQLAlchemy) is imported by the handlers only: building the `pbdag` parser
stays fast for every other command.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import sqlalchemy as sa

__all__ = ["access_summary", "register", "serve_refusal"]


def register(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add `token` and its subcommands to the `pbdag` parser."""
    token = commands.add_parser("token", help="create, list and revoke API bearer tokens")
    actions = token.add_subparsers(
        dest="token_command", required=True, help="what to do with tokens"
    )

    create = actions.add_parser(
        "create", help="create a token and print it (once: only its hash is stored)"
    )
    create.add_argument("--name", required=True, help="who or what uses it, e.g. robot-1")
    create.add_argument(
        "--scope",
        dest="scopes",
        action="append",
        required=True,
        metavar="{read,write,admin}",
        help="what the token may do (repeatable): read, write or admin; admin implies write, "
        "write implies read",
    )
    create.set_defaults(handler=_create)

    listing = actions.add_parser("list", help="every token: id, name, scopes, created, revoked")
    listing.set_defaults(handler=_list)

    revoke = actions.add_parser("revoke", help="revoke a token by its id (see `pbdag token list`)")
    revoke.add_argument("id", metavar="ID", help="the token's id, the first column of the list")
    revoke.set_defaults(handler=_revoke)


def _engine() -> sa.Engine:
    from service.cli_support import open_container

    return open_container().engine


def _create(args: argparse.Namespace) -> int:
    from service.auth import create_token

    engine = _engine()  # its SettingsError is main's to report, not a scope's
    try:
        created = create_token(engine, args.name, args.scopes)
    except ValueError as error:
        print(f"pbdag token create: {error}", file=sys.stderr)
        return 2
    record = created.record
    # The token alone on stdout (TOKEN=$(pbdag token create ...)); the notes on stderr.
    print(
        f"created token {record.id} ({record.name}) with scopes {', '.join(record.scopes)}.\n"
        "Copy it now: it cannot be shown again (only its sha256 is stored).\n"
        "Clients send it as:  Authorization: Bearer <token>",
        file=sys.stderr,
    )
    print(created.token, flush=True)
    return 0


def _list(_args: argparse.Namespace) -> int:
    from service.auth import list_tokens

    records = list_tokens(_engine())
    if not records:
        print("no tokens; create one with: pbdag token create --name NAME --scope read")
        return 0
    print(f"{'id':<12}  {'name':<24} {'scopes':<18} {'created (UTC)':<20} revoked (UTC)")
    for record in records:
        print(
            f"{record.id:<12}  {record.name:<24} {','.join(record.scopes):<18} "
            f"{_when(record.created_at):<20} {_when(record.revoked_at)}"
        )
    return 0


def _revoke(args: argparse.Namespace) -> int:
    from service.auth import UnknownToken, revoke_token

    try:
        record = revoke_token(_engine(), args.id)
    except UnknownToken as error:
        print(f"pbdag token revoke: {error} (see `pbdag token list`)", file=sys.stderr)
        return 1
    print(f"token {record.id} ({record.name}) revoked at {_when(record.revoked_at)} UTC")
    return 0


def _when(timestamp: float | None) -> str:
    if timestamp is None:
        return "-"
    return datetime.fromtimestamp(timestamp, UTC).strftime("%Y-%m-%d %H:%M:%S")


def serve_refusal(host: str, engine: sa.Engine) -> str | None:
    """Why `pbdag serve --host HOST` must not start, or None: a non-loopback address needs at
    least one active token, so that nobody puts the robot's memory on the LAN unprotected."""
    from service.auth import has_active_token, is_loopback

    if is_loopback(host) or has_active_token(engine):
        return None
    return (
        f"pbdag serve: refusing to listen on {host}: it is reachable from the network and no API "
        "token is configured.\n"
        "Create a token first (it is printed once):\n"
        "    pbdag token create --name robot-1 --scope write\n"
        "then have every client send it:\n"
        "    Authorization: Bearer <token>\n"
        "Or serve on this machine only: pbdag serve --host 127.0.0.1"
    )


def access_summary(engine: sa.Engine, allow_anonymous_local: bool) -> str:
    """One line for `pbdag serve`: who will be able to use the API, and how to change it."""
    from service.auth import list_tokens

    active = sum(record.active for record in list_tokens(engine))
    anonymous = "on" if allow_anonymous_local else "off"
    line = f"pbdag: {active} active API token(s); anonymous local access {anonymous}"
    if active == 0 and not allow_anonymous_local:
        line += (
            ": every request but /healthz will get a 401. Create a token "
            "(pbdag token create --name NAME --scope write) or set PBDAG_ALLOW_ANONYMOUS_LOCAL=true"
        )
    return line
