"""The OpenAPI document: FastAPI's, plus what it cannot infer.

- Every error status an operation can answer, with the problem+json body (RFC 9457) that the
  one problem table (service/errors.py) produces. FastAPI's own 422 schema is replaced: our
  validation errors are problems too.
- The bearer scheme (service/auth.py): every operation needs it but the open liveness probe.

FastAPI's documented way to extend the document is to wrap `app.openapi`; the result is cached.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

from api_schema import Problem
from service.errors import PROBLEM_MEDIA_TYPE

BEARER_SCHEME = "bearer"
OPEN_PATHS = frozenset({"/healthz"})  # liveness probes carry no token

# Every operation: Host check (400), authentication (401, 403), validation (422), rate limits
# (429), and the unexpected (500).
COMMON = {
    400: "The Host header names a host this service does not answer for.",
    401: "No valid bearer token.",
    403: "The token lacks the scope the request needs.",
    422: "A field is invalid: `field` names it.",
    429: "Too many requests (rate limit, or the scene's queue is full): see Retry-After.",
    500: "The server failed; nothing was changed.",
    503: "The database or the blob store is unavailable for a moment: retry after Retry-After.",
}
SCENE = {
    404: "The scene, or what the path names in it, does not exist (or `as_of` is past the head).",
    409: "The scene is quarantined or needs repair, or the request conflicts with its state.",
}
BODY = {413: "The request body is over the limit (PBDAG_MAX_BODY_BYTES)."}
STORAGE = {507: "The scene's raw batches would exceed its quota (PBDAG_MAX_SCENE_BLOB_BYTES)."}
GONE = {410: "The batch's raw body was deleted by `pbdag gc` (PBDAG_RAW_RETENTION)."}
OPEN = {400: COMMON[400], 500: COMMON[500], 503: COMMON[503]}
LISTING = {404: "`after` names no scene."}
STREAM = {
    503: "The database is unavailable for a moment, or this server already serves "
    "PBDAG_MAX_STREAMS event streams: retry after Retry-After (or on another server)."
}


def error_statuses(path: str, method: str) -> dict[int, str]:
    """The error statuses one operation documents."""
    if path in OPEN_PATHS:
        return OPEN
    statuses = dict(COMMON)
    if "{scene_id}" in path or method != "get":
        statuses |= SCENE
    if method in ("post", "put", "patch"):
        statuses |= BODY
    if path.endswith("/batches") and method == "post":
        statuses |= STORAGE
    if path.endswith("/requeue"):
        statuses |= GONE
    if path == "/v1/scenes" and method == "get":
        statuses |= LISTING
    if path.endswith("/events/stream"):
        statuses |= STREAM
    return statuses


def install_openapi(app: FastAPI) -> None:
    """Make `app.openapi()` return the extended document."""
    generate = app.openapi
    extended: dict[str, Any] = {}

    def document() -> dict[str, Any]:
        if extended:
            return extended
        schema = generate()
        components = schema.setdefault("components", {})
        schemas = components.setdefault("schemas", {})
        schemas["Problem"] = Problem.model_json_schema(ref_template="#/components/schemas/{model}")
        for name, definition in schemas["Problem"].pop("$defs", {}).items():
            schemas[name] = definition
        for name in ("HTTPValidationError", "ValidationError"):
            schemas.pop(name, None)
        problem = {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}}
        for path, operations in schema.get("paths", {}).items():
            for method, operation in operations.items():
                responses = operation.setdefault("responses", {})
                for status, description in error_statuses(path, method).items():
                    responses[str(status)] = {"description": description, "content": problem}
        components.setdefault("securitySchemes", {})[BEARER_SCHEME] = {
            "type": "http",
            "scheme": "bearer",
            "description": (
                "`Authorization: Bearer pbdag_<id>_<secret>`, from `pbdag token create`. "
                "Scopes: GET needs `read`, other methods `write`; `admin` implies both."
            ),
        }
        schema["security"] = [{BEARER_SCHEME: []}]
        for path in OPEN_PATHS:
            for operation in schema.get("paths", {}).get(path, {}).values():
                operation["security"] = []
        extended.update(schema)
        return extended

    app.openapi = document  # type: ignore[method-assign]
