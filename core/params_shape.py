"""The shape a scene's parameter overrides may have, checked before anything else reads them.

The parameter tree is at most four levels deep (`fixtures.size_limits.table[0]`), its maps are
keyed by the taxonomy's labels (at most 64) and its lists are short tuples. Overrides far
outside that shape are refused in one pass over the JSON value, without recursion, before they
are merged, encoded or validated: a map of 500,000 keys, an integer past 2^53 (beyond what a
JSON number holds exactly, and past 64 bits the encoder refuses it) or nesting hundreds of
levels deep would otherwise cost seconds of CPU or reach a recursion limit.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.errors import InvalidParams, field_path

MAX_DEPTH = 6  # containers within containers; the tree itself needs 4
MAX_KEYS = 64  # keys of one map: the taxonomy's most labels
MAX_ITEMS = 64  # items of one list: a taxonomy of 64 labels
MAX_NODES = 4096  # values in all
MAX_TEXT = 200  # characters of one string (labels are 1-100)
MAX_EXACT_INT = 2**53  # integers a JSON number carries exactly


def check_shape(overrides: Mapping[str, Any]) -> None:
    """Raise InvalidParams naming the first value of `overrides` outside the shape above."""
    pending: list[tuple[Any, list[str | int]]] = [(overrides, [])]
    nodes = 0
    while pending:
        value, location = pending.pop()
        nodes += 1
        if nodes > MAX_NODES:
            _refuse(location, f"at most {MAX_NODES} values in all")
        if isinstance(value, Mapping | list | tuple) and len(location) >= MAX_DEPTH:
            _refuse(location, f"nested deeper than {MAX_DEPTH} levels")
        if isinstance(value, Mapping):
            if len(value) > MAX_KEYS:
                _refuse(location, f"at most {MAX_KEYS} keys in one object, got {len(value)}")
            for key, item in value.items():
                if not isinstance(key, str) or len(key) > MAX_TEXT:
                    _refuse(location, f"keys are strings of at most {MAX_TEXT} characters")
                pending.append((item, [*location, key]))
        elif isinstance(value, list | tuple):
            if len(value) > MAX_ITEMS:
                _refuse(location, f"at most {MAX_ITEMS} items in one list, got {len(value)}")
            pending.extend((item, [*location, index]) for index, item in enumerate(value))
        elif isinstance(value, str) and len(value) > MAX_TEXT:
            _refuse(location, f"at most {MAX_TEXT} characters")
        elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_EXACT_INT:
            _refuse(location, "an integer beyond 2^53 is outside every range")


def _refuse(location: list[str | int], reason: str) -> None:
    path = field_path(["params", *location]) or "params"
    raise InvalidParams(f"{path}: {reason}", path)
