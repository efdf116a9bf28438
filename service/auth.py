"""Bearer tokens with scopes: hashed storage, verification, the access errors, the scope dependency.

A token is `pbdag_<id>_<secret>`: `<id>` is public (it names the token in `pbdag token list`),
`<secret>` is 32 random bytes. Only the sha256 of the whole token is stored.

Scopes nest: `admin` implies `write`, which implies `read`. Requests are checked by
`service.security.AccessControl` (GET/HEAD/OPTIONS need `read`, other methods `write`);
routes that need more declare it with `RequireAdmin` (or `Depends(require_scope(...))`).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import re
import secrets
import time
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import Annotated, Literal

import sqlalchemy as sa
from fastapi import Depends, Request

from pbdag_errors import Refused
from service.access_errors import InsufficientScope, NotAuthenticated
from service.store.engine import read_transaction, write_transaction
from service.store.tables import api_tokens

__all__ = [
    "ANONYMOUS_LOCAL_SCOPES",
    "SCOPES",
    "NewToken",
    "Principal",
    "RequireAdmin",
    "Scope",
    "TokenRecord",
    "UnknownToken",
    "authenticate",
    "authorize",
    "create_token",
    "has_active_token",
    "is_loopback",
    "list_tokens",
    "require_scope",
    "revoke_token",
    "scope_for_method",
    "verify_token",
]

Scope = Literal["read", "write", "admin"]
SCOPES: tuple[Scope, ...] = ("read", "write", "admin")
_IMPLIED: dict[Scope, frozenset[Scope]] = {
    "read": frozenset({"read"}),
    "write": frozenset({"read", "write"}),
    "admin": frozenset({"read", "write", "admin"}),
}
# Anonymous loopback clients (PBDAG_ALLOW_ANONYMOUS_LOCAL) may post batches and verdicts and read
# everything, but never administer: managing the service always takes a deliberate token.
ANONYMOUS_LOCAL_SCOPES: frozenset[Scope] = _IMPLIED["write"]
# Methods that change nothing need `read`; every other method needs `write`.
_READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})

TOKEN_PREFIX = "pbdag_"
_ID_BYTES = 6  # 12 hex characters
_SECRET_BYTES = 32
_TOKEN_FORMAT = re.compile(r"pbdag_([0-9a-f]{12})_([A-Za-z0-9_-]{20,100})")
_MAX_NAME_LENGTH = 200


def effective_scopes(granted: Iterable[Scope]) -> frozenset[Scope]:
    """Granted scopes with the ones they imply (admin -> write -> read)."""
    return frozenset().union(*(_IMPLIED[scope] for scope in granted))


def scope_for_method(method: str) -> Scope:
    """The scope a request of this HTTP method needs."""
    return "read" if method.upper() in _READ_METHODS else "write"


def is_loopback(host: str | None) -> bool:
    """True for 127.0.0.0/8, ::1 (also IPv4-mapped) and `localhost`; False for anything else."""
    if not host:
        return False
    host = host.strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped.is_loopback
    return address.is_loopback


# --- stored tokens ---------------------------------------------------------------------------


@dataclass(frozen=True)
class TokenRecord:
    """A stored token, without its hash."""

    id: str
    name: str
    scopes: tuple[Scope, ...]
    created_at: float
    revoked_at: float | None

    @property
    def active(self) -> bool:
        """Not revoked."""
        return self.revoked_at is None


@dataclass(frozen=True)
class NewToken:
    """A token just created: the only moment its secret exists outside the client."""

    record: TokenRecord
    token: str


class UnknownToken(Refused, LookupError):
    """No token with this id (`pbdag token revoke`; never a request's answer)."""

    def __init__(self, token_id: str) -> None:
        super().__init__(f"no token with id {token_id!r}", "token_id")
        self.token_id = token_id


def token_digest(token: str) -> str:
    """The stored form of a token.

    A plain sha256, no salt or slow KDF: those protect low-entropy passwords against guessing,
    while these secrets are 256 random bits that no offline search can find.
    """
    return hashlib.sha256(token.encode()).hexdigest()


def _canonical_scopes(scopes: Iterable[str]) -> tuple[Scope, ...]:
    wanted = set(scopes)
    unknown = wanted - set(SCOPES)
    if unknown:
        raise ValueError(f"unknown scopes {sorted(unknown)}; choose from {', '.join(SCOPES)}")
    if not wanted:
        raise ValueError("a token needs at least one scope")
    return tuple(scope for scope in SCOPES if scope in wanted)


def _record(mapping: sa.RowMapping) -> TokenRecord:
    return TokenRecord(
        id=str(mapping["id"]),
        name=str(mapping["name"]),
        scopes=_canonical_scopes(str(mapping["scopes"]).split()),
        created_at=float(mapping["created_at"]),
        revoked_at=None if mapping["revoked_at"] is None else float(mapping["revoked_at"]),
    )


_PUBLIC_COLUMNS = (
    api_tokens.c.id,
    api_tokens.c.name,
    api_tokens.c.scopes,
    api_tokens.c.created_at,
    api_tokens.c.revoked_at,
)


def create_token(
    engine: sa.Engine,
    name: str,
    scopes: Iterable[str],
    *,
    clock: Callable[[], float] = time.time,
) -> NewToken:
    """Create and store a token; the returned `token` is never retrievable again."""
    name = name.strip()
    if not name or len(name) > _MAX_NAME_LENGTH:
        raise ValueError(f"a token name has 1 to {_MAX_NAME_LENGTH} characters")
    granted = _canonical_scopes(scopes)
    for _attempt in range(3):  # a 48-bit id collides practically never; retry if it does
        token_id = secrets.token_hex(_ID_BYTES)
        token = f"{TOKEN_PREFIX}{token_id}_{secrets.token_urlsafe(_SECRET_BYTES)}"
        record = TokenRecord(token_id, name, granted, clock(), None)
        try:
            with write_transaction(engine) as connection:
                connection.execute(
                    sa.insert(api_tokens).values(
                        id=token_id,
                        name=name,
                        scopes=" ".join(granted),
                        token_sha256=token_digest(token),
                        created_at=record.created_at,
                        revoked_at=None,
                    )
                )
        except sa.exc.IntegrityError:
            continue
        return NewToken(record, token)
    raise RuntimeError("could not allocate a unique token id")


def list_tokens(engine: sa.Engine) -> list[TokenRecord]:
    """Every token, oldest first (revoked ones included)."""
    with read_transaction(engine) as connection:
        rows = connection.execute(
            sa.select(*_PUBLIC_COLUMNS).order_by(api_tokens.c.created_at, api_tokens.c.id)
        ).all()
    return [_record(row._mapping) for row in rows]


def revoke_token(
    engine: sa.Engine, token_id: str, *, clock: Callable[[], float] = time.time
) -> TokenRecord:
    """Revoke a token from now on; revoking it again keeps the first revocation time."""
    with write_transaction(engine) as connection:
        connection.execute(
            sa.update(api_tokens)
            .where(api_tokens.c.id == token_id, api_tokens.c.revoked_at.is_(None))
            .values(revoked_at=clock())
        )
        row = connection.execute(
            sa.select(*_PUBLIC_COLUMNS).where(api_tokens.c.id == token_id)
        ).first()
    if row is None:
        raise UnknownToken(token_id)
    return _record(row._mapping)


def verify_token(engine: sa.Engine, token: str) -> TokenRecord | None:
    """The record of this exact token (possibly revoked), or None when it is not one of ours."""
    match = _TOKEN_FORMAT.fullmatch(token)
    if match is None:
        return None
    with read_transaction(engine) as connection:
        row = connection.execute(
            sa.select(*_PUBLIC_COLUMNS, api_tokens.c.token_sha256).where(
                api_tokens.c.id == match.group(1)
            )
        ).first()
    if row is None:
        return None
    # Constant-time comparison: the time taken reveals nothing about how much of the hash matched.
    if not hmac.compare_digest(str(row.token_sha256), token_digest(token)):
        return None
    return _record(row._mapping)


def has_active_token(engine: sa.Engine) -> bool:
    """True when at least one token is not revoked."""
    with read_transaction(engine) as connection:
        found = connection.execute(
            sa.select(api_tokens.c.id).where(api_tokens.c.revoked_at.is_(None)).limit(1)
        ).first()
    return found is not None


# --- who is asking ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Principal:
    """The authenticated client of one request."""

    kind: Literal["token", "anonymous-local"]
    scopes: frozenset[Scope]
    rate_key: str  # whose bucket the request is charged to
    token_id: str | None = None
    name: str | None = None

    def describe(self) -> str:
        """For messages: which token, or the anonymous local client."""
        if self.kind == "token":
            return f"token {self.token_id} ({self.name})"
        return "an anonymous local client"


def address_key(client_host: str | None) -> str:
    """The rate-limit key of a client address."""
    return f"address:{client_host or 'unknown'}"


def _bearer_credentials(authorization: str) -> str | None:
    scheme, _, credentials = authorization.strip().partition(" ")
    credentials = credentials.strip()
    if scheme.lower() != "bearer" or not credentials:
        return None
    return credentials


def authenticate(
    authorization: str | None,
    client_host: str | None,
    *,
    engine: sa.Engine,
    allow_anonymous_local: bool,
) -> Principal:
    """Who sends this request; raises NotAuthenticated when nobody acceptable does.

    A presented token must be valid even from loopback: anonymous access never papers over a
    bad token.
    """
    if authorization is None:
        if allow_anonymous_local and is_loopback(client_host):
            return Principal("anonymous-local", ANONYMOUS_LOCAL_SCOPES, address_key(client_host))
        raise NotAuthenticated(
            "this request needs a bearer token: send `Authorization: Bearer <token>` "
            "(an operator creates one with `pbdag token create`)"
        )
    token = _bearer_credentials(authorization)
    if token is None:
        raise NotAuthenticated(
            "the Authorization header must be `Bearer <token>`", token_error="invalid_request"
        )
    record = verify_token(engine, token)
    if record is None:
        raise NotAuthenticated("the bearer token is not valid", token_error="invalid_token")
    if not record.active:
        raise NotAuthenticated("the bearer token was revoked", token_error="invalid_token")
    return Principal(
        "token",
        effective_scopes(record.scopes),
        f"token:{record.id}",
        token_id=record.id,
        name=record.name,
    )


def authorize(principal: Principal, needed: Scope) -> None:
    """Raise InsufficientScope unless the principal holds `needed` (directly or implied)."""
    if needed not in principal.scopes:
        held = ", ".join(scope for scope in SCOPES if scope in principal.scopes) or "none"
        raise InsufficientScope(
            f"this request needs the '{needed}' scope; {principal.describe()} has: {held}",
            needed=needed,
        )


# --- route dependencies ----------------------------------------------------------------------


def require_scope(needed: Scope) -> Callable[[Request], Awaitable[Principal]]:
    """A dependency: the request's principal (set by AccessControl), which must hold `needed`."""

    async def principal_with_scope(request: Request) -> Principal:
        principal = getattr(request.state, "principal", None)
        if not isinstance(principal, Principal):
            # Fail closed: an app without AccessControl in front never serves a scoped route.
            raise NotAuthenticated("this request needs a bearer token")
        authorize(principal, needed)
        return principal

    return principal_with_scope


RequireAdmin = Annotated[Principal, Depends(require_scope("admin"))]
