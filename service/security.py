"""The LAN boundary of the app: allowed Host names, CORS, bearer tokens with scopes, rate limits.

Order of the layers, outermost first (`install_security` adds them):

    AllowedHosts (DNS rebinding) -> CORS (optional) -> AccessControl -> body limit -> routes

AccessControl authenticates before anything reads the request body, so a client without a
valid token can make the service read neither a 64 MiB batch nor a line of JSON.
"""

from __future__ import annotations

import ipaddress
import math
import re
from collections.abc import Sequence

from fastapi import FastAPI
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import Headers
from starlette.middleware.cors import CORSMiddleware
from starlette.types import ASGIApp, Receive, Scope, Send

from service.access_errors import (
    AUTH_FIELD,
    AccessProblem,
    HostNotAllowed,
    InsufficientScope,
    NotAuthenticated,
    RateLimitExceeded,
)
from service.auth import (
    Principal,
    address_key,
    authenticate,
    authorize,
    scope_for_method,
)
from service.bootstrap import Container
from service.errors import send_problem
from service.openapi import OPEN_PATHS
from service.ratelimit import RateLimiter
from service.viewer import STATIC_PREFIX, VIEWER_PATH

__all__ = [
    "OPEN_PATHS",
    "AccessControl",
    "AllowedHosts",
    "install_security",
    "parse_host",
]

# Static pages and files hold no scene data, and a browser must load the viewer before its user
# can type a token; the viewer sends the token with every API request.
OPEN_PAGES = frozenset({VIEWER_PATH})
OPEN_PREFIXES = (f"{STATIC_PREFIX}/",)
# A request carrying one of these says a proxy forwarded it: it is never anonymous local access.
FORWARDING_HEADERS = ("x-forwarded-for", "forwarded")


def is_open(path: str) -> bool:
    """True for the paths that need no token: liveness probes, the viewer page, static files."""
    return path in OPEN_PATHS or path in OPEN_PAGES or path.startswith(OPEN_PREFIXES)


# --- Host names -------------------------------------------------------------------------------


_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")
_DIGITS = re.compile(r"[0-9]+")
_PORT = re.compile(r":([0-9]{1,5})")


def parse_host(host_header: str) -> str | None:
    """The host a Host header names (lower case, an IPv6 address without brackets), or None
    unless the header is exactly a host, then optionally `:port` (1-5 digits, 1 to 65535).

    A host is one of:
    - a DNS name: labels of letters, digits and hyphens (1-63 characters, no hyphen first or
      last) joined by single dots, at most 253 characters; one trailing dot, the absolute form
      of the same name, is accepted and dropped (`localhost.` is `localhost`, `localhost..` is
      refused);
    - an IPv4 literal in dotted decimal (a name whose last label is a number must be one);
    - an IPv6 literal in brackets, without a zone.
    Anything else (`localhost:80@evil.com`, `[::1]evil.com`, spaces) is refused.
    """
    if host_header.startswith("["):
        end = host_header.find("]")
        host = _ipv6_literal(host_header[1:end]) if end > 0 else None
        rest = host_header[end + 1 :] if end > 0 else ""
    else:
        name, colon, port = host_header.partition(":")
        host = _name_or_ipv4(name)
        rest = colon + port
    if host is None:
        return None
    if rest:
        port_match = _PORT.fullmatch(rest)
        if port_match is None or not 1 <= int(port_match.group(1)) <= 65535:
            return None
    return host


def _ipv6_literal(text: str) -> str | None:
    if "%" in text:  # a zone names an interface of the client, not this host
        return None
    try:
        return str(ipaddress.IPv6Address(text))
    except ValueError:
        return None


def _name_or_ipv4(name: str) -> str | None:
    bare = name[:-1] if name.endswith(".") else name
    labels = bare.split(".")
    if len(bare) > 253 or not all(_LABEL.fullmatch(label) for label in labels):
        return None
    if _DIGITS.fullmatch(labels[-1]):  # no top-level domain is numeric: an IPv4 literal
        if bare != name:
            return None
        try:
            return str(ipaddress.IPv4Address(bare))
        except ValueError:
            return None
    return bare.lower()


def _pattern_name(pattern: str) -> str:
    """A PBDAG_ALLOWED_HOSTS entry (or a bind address) as `parse_host` gives names: lower case,
    no port, no brackets or trailing dot, addresses in their canonical form; `*` patterns kept."""
    host = pattern.strip().lower()
    if host.startswith("["):  # [::1]:8000
        host = host[1 : host.find("]")] if "]" in host else host
    elif host.count(":") == 1:  # name:port (a bare IPv6 address has several colons)
        host = host.split(":", 1)[0]
    host = host.rstrip(".")
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host


class AllowedHosts:
    """Pure ASGI middleware: 400 problem+json unless the Host header names an allowed host.

    A header `parse_host` refuses is refused whatever is allowed, `*` included.
    """

    def __init__(self, app: ASGIApp, allowed: Sequence[str]) -> None:
        self.app = app
        patterns = {_pattern_name(name) for name in allowed if name.strip()}
        self.any_host = "*" in patterns
        self.suffixes = tuple(p[1:] for p in patterns if p.startswith("*."))  # ".example.org"
        self.names = frozenset(p for p in patterns if not p.startswith("*"))

    def allows(self, host_header: str) -> bool:
        """True when the header is well-formed and its host is listed, or matches a `*.domain`
        pattern (or `*` is allowed)."""
        name = parse_host(host_header)
        if name is None:
            return False
        return self.any_host or name in self.names or name.endswith(self.suffixes)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check every HTTP request (and refuse websockets from foreign hosts)."""
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        host = Headers(scope=scope).get("host", "")
        if self.allows(host):
            await self.app(scope, receive, send)
        elif scope["type"] == "http":
            await send_problem(send, HostNotAllowed(host))
        else:
            await send({"type": "websocket.close", "code": 1008})


def hosts_when_serving(allowed: Sequence[str], bind_host: str) -> list[str]:
    """The allowed hosts plus the address the server binds (not a wildcard, which no client names)."""
    if _pattern_name(bind_host) in ("0.0.0.0", "::", "") or bind_host in allowed:
        return list(allowed)
    return [*allowed, bind_host]


# --- tokens, scopes, rate limits ---------------------------------------------------------------


class AccessControl:
    """Pure ASGI middleware: authenticate, rate-limit and check the method's scope.

    GET/HEAD/OPTIONS need `read`, other methods `write`; open paths (`is_open`) need nothing.
    The principal is left in `request.state.principal` for routes that need more (RequireAdmin).

    The client address (the rate-limit key of anonymous requests and failed attempts) is the
    socket's peer, or what X-Forwarded-For says when the peer is one of PBDAG_TRUSTED_PROXIES
    (`pbdag serve` has uvicorn read the header from those only). Anonymous local access never
    rests on a header: it needs the socket's peer to be a loopback address that is no trusted
    proxy, in a request that does not say it was forwarded (no X-Forwarded-For or Forwarded).
    """

    def __init__(
        self,
        app: ASGIApp,
        *,
        container: Container,
        limiter: RateLimiter | None,
    ) -> None:
        self.app = app
        self.engine = container.engine
        self.allow_anonymous_local = container.settings.allow_anonymous_local
        self.trusted_proxies = tuple(
            ipaddress.ip_network(entry, strict=False)
            for entry in container.settings.trusted_proxies
        )
        self.limiter = limiter

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Answer 401, 403 or 429 here, before the app reads anything of the request."""
        if scope["type"] != "http" or is_open(_route_path(scope)):
            await self.app(scope, receive, send)
            return
        try:
            principal = await self._principal(scope)
            self._charge(principal.rate_key, AUTH_FIELD if principal.kind == "token" else None)
            authorize(principal, scope_for_method(scope["method"]))
        except NotAuthenticated as unauthorized:
            answer: AccessProblem = unauthorized
            # Failed attempts are charged to the address, so a flood of guesses is throttled too.
            try:
                self._charge(address_key(_client_host(scope)), None)
            except RateLimitExceeded as limited:
                answer = limited
            await send_problem(send, answer)
            return
        except (InsufficientScope, RateLimitExceeded) as problem:
            await send_problem(send, problem)
            return
        scope.setdefault("state", {})["principal"] = principal
        await self.app(scope, receive, send)

    async def _principal(self, scope: Scope) -> Principal:
        values = Headers(scope=scope).getlist("authorization")
        if len(values) > 1:
            raise NotAuthenticated("send one Authorization header", token_error="invalid_request")
        authorization = values[0] if values else None
        client_host = _client_host(scope)
        anonymous = self.allow_anonymous_local and self._from_the_peer(scope, client_host)
        if authorization is None:  # no database involved: stay on the event loop
            return authenticate(
                None, client_host, engine=self.engine, allow_anonymous_local=anonymous
            )
        return await run_in_threadpool(
            authenticate,
            authorization,
            client_host,
            engine=self.engine,
            allow_anonymous_local=anonymous,
        )

    def _from_the_peer(self, scope: Scope, client_host: str | None) -> bool:
        """True when `client_host` is certainly the socket's peer: the request does not say it
        was forwarded, and the address is no trusted proxy (whose clients it stands for)."""
        headers = Headers(scope=scope)
        if any(name in headers for name in FORWARDING_HEADERS):
            return False
        try:
            address = ipaddress.ip_address(client_host or "")
        except ValueError:
            return True  # no address (a test client's name): authenticate finds it no loopback
        return not any(address in network for network in self.trusted_proxies)

    def _charge(self, key: str, field: str | None) -> None:
        if self.limiter is None:
            return
        wait = self.limiter.acquire(key)
        if wait > 0:
            raise RateLimitExceeded(
                max(1, math.ceil(wait)), per_minute=self.limiter.per_minute, field=field
            )


def _client_host(scope: Scope) -> str | None:
    client = scope.get("client")
    return str(client[0]) if client else None


def _route_path(scope: Scope) -> str:
    path = str(scope["path"])
    root_path = str(scope.get("root_path", ""))
    if root_path and path.startswith(root_path):
        return path[len(root_path) :] or "/"
    return path


# --- wiring -----------------------------------------------------------------------------------


def install_security(app: FastAPI, container: Container) -> None:
    """Add the layers above (after every other middleware, so they run first)."""
    settings = container.settings
    limiter = (
        RateLimiter(settings.rate_limit_per_minute, settings.rate_limit_burst)
        if settings.rate_limit_per_minute > 0
        else None
    )
    app.add_middleware(AccessControl, container=container, limiter=limiter)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
            expose_headers=["Retry-After", "WWW-Authenticate"],
        )
    app.add_middleware(AllowedHosts, allowed=settings.allowed_hosts)
