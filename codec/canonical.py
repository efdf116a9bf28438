"""The canonical JSON of a request body: what a batch's blob holds, and its content hash."""

from __future__ import annotations

import hashlib
from typing import Any

import orjson


def canonical_json(body: dict[str, Any]) -> bytes:
    """The canonical JSON of `body` (sorted keys, no whitespace): what a batch's blob holds."""
    return orjson.dumps(body, option=orjson.OPT_SORT_KEYS)


def content_sha256(body: dict[str, Any]) -> str:
    """Hex sha256 of the canonical JSON of `body`."""
    return hashlib.sha256(canonical_json(body)).hexdigest()
