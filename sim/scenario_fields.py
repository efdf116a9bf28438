"""Field types of scenario files and the one error they raise, which names the offending field.

Every part of a file is a frozen dataclass whose fields carry their ranges (pydantic, as
`core/params.py` checks the method's parameters): strict types (no "525" for a number, no true
for an integer), finite numbers, no unknown keys. `validated` turns pydantic's first error into
a `ScenarioError` that starts with the field's path as the file spells it (`objects[3].size`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Annotated, Any, TypeVar

from pydantic import (
    AfterValidator,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    TypeAdapter,
    ValidationError,
)
from pydantic_core import ErrorDetails, PydanticCustomError

from core.errors import field_path
from pbdag_errors import Refused

T = TypeVar("T")


class ScenarioError(Refused, ValueError):
    """A scenario file that cannot be used; the message starts with the offending field."""


# Strict scalars (no "525" for a number, no true for an integer, an integer is a number),
# finite numbers, no unknown keys. The scalar types carry the strictness: a strict model would
# take lists for tuples and mappings for parts only from JSON, and the parts reshape some input.
CHECKED = ConfigDict(extra="forbid", allow_inf_nan=False)

Number = StrictFloat  # any finite number
NonNegative = Annotated[StrictFloat, Field(ge=0.0)]
Positive = Annotated[StrictFloat, Field(gt=0.0)]
Fraction = Annotated[StrictFloat, Field(ge=0.0, le=1.0)]  # a probability or a share
Count = Annotated[StrictInt, Field(ge=0)]
PositiveInt = Annotated[StrictInt, Field(gt=0)]
Text = Annotated[StrictStr, Field(pattern=r"\S")]  # a non-empty string
Flag = StrictBool
Vec2 = tuple[Number, Number]
Vec3 = tuple[Number, Number, Number]
Size3 = tuple[Positive, Positive, Positive]  # a box's extents: every side > 0


def field_error(field: str, message: str) -> PydanticCustomError:
    """An error about `field` of the part being checked (a name, or an index like `[2].id`)."""
    return PydanticCustomError("scenario_field", message, {"field": field})


def ordered(pair: tuple[Any, Any]) -> tuple[Any, Any]:
    if pair[0] > pair[1]:
        raise ValueError(f"low {pair[0]} exceeds high {pair[1]}")
    return pair


FractionPair = Annotated[tuple[Fraction, Fraction], AfterValidator(ordered)]  # [low, high]
CountPair = Annotated[tuple[Count, Count], AfterValidator(ordered)]


def _keep_nulls(value: Any, path: tuple[str, ...], nullable: set[tuple[str, ...]]) -> Any:
    """The file's values with `null` dropped (it counts as absent) except where it means None."""
    if isinstance(value, Mapping):
        return {
            str(key): _keep_nulls(item, (*path, str(key)), nullable)
            for key, item in value.items()
            if item is not None or (*path, str(key)) in nullable
        }
    if isinstance(value, list | tuple):
        return [_keep_nulls(item, path, nullable) for item in value]
    return value


def _shown(value: Any) -> str:
    """A value as the file would spell it."""
    return repr(json.loads(json.dumps(value))) if isinstance(value, list | dict) else repr(value)


def _reason(error: ErrorDetails) -> str:
    """Pydantic's message for one error, in the words of the old field checks."""
    kind, ctx, got = error["type"], error.get("ctx") or {}, _shown(error["input"])
    bounds = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<"}
    bounds["less_than_equal"] = "<="
    if kind in bounds:
        return f"must be {bounds[kind]} {next(iter(ctx.values()))}, got {got}"
    if kind == "missing":
        return "required"
    if kind == "unexpected_keyword_argument":
        return "unknown field"
    if kind == "too_short":
        return f"expected at least {ctx['min_length']} entries, got {got}"
    if kind == "too_long":
        return f"expected at most {ctx['max_length']} entries, got {got}"
    if kind == "dataclass_type":
        return f"expected a mapping of fields, got {got}"
    if kind == "string_pattern_mismatch":  # the one pattern: Text
        return f"expected a non-empty string, got {got}"
    message = error["msg"].removeprefix("Value error, ")
    if kind == "scenario_field" or kind == "value_error":
        return message
    return f"{message.replace('Input should be', 'expected')}, got {got}"


def validated(
    adapter: TypeAdapter[T], data: Mapping[str, Any], nullable: set[tuple[str, ...]]
) -> T:
    """`data` checked by `adapter`; `null` is absent except at the `nullable` key paths."""
    try:
        text = json.dumps(_keep_nulls(data, (), nullable))
    except (TypeError, ValueError) as error:  # a YAML date or set: no value of a scenario
        raise ScenarioError(
            f"scenario: only numbers, strings, lists and mappings ({error})"
        ) from None
    try:
        return adapter.validate_json(text)
    except ValidationError as error:
        first = error.errors()[0]
        location = [part for part in first["loc"] if not str(part).startswith("function-")]
        field = str((first.get("ctx") or {}).get("field", ""))  # named by a part's own check
        if first["type"] == "missing" and location and isinstance(location[-1], int):
            # A list too short for its fixed length: pydantic reports the first missing entry.
            location.pop()
            reason = f"too few entries, got {_shown(first['input'])}"
        else:
            reason = _reason(first)
        path = field_path(location) or ""
        if first["type"] == "scenario_field":
            path += field if field.startswith("[") or not path else f".{field}"
        raise ScenarioError(f"{path or 'scenario'}: {reason}") from None
