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
    """A [low, high] pair with low <= high."""
    if pair[0] > pair[1]:
        raise ValueError(f"low {pair[0]} exceeds high {pair[1]}")
    return pair


FractionPair = Annotated[tuple[Fraction, Fraction], AfterValidator(ordered)]  # [low, high]
CountPair = Annotated[tuple[Count, Count], AfterValidator(ordered)]


def _nulls_dropped(value: Any, path: tuple[str, ...], nullable: set[tuple[str, ...]]) -> Any:
    """The file's values with `null` dropped (it counts as absent) except where it means None."""
    if isinstance(value, Mapping):
        return {
            str(key): _nulls_dropped(item, (*path, str(key)), nullable)
            for key, item in value.items()
            if item is not None or (*path, str(key)) in nullable
        }
    if isinstance(value, list | tuple):
        return [_nulls_dropped(item, path, nullable) for item in value]
    return value


def _schema_at(schema: dict[str, Any], location: list[str | int]) -> dict[str, Any]:
    """The JSON schema of the field at `location` ({} where the walk cannot follow)."""
    node = schema
    for part in [*location, None]:
        while "$ref" in node or "anyOf" in node:  # a part, or an optional one
            if "$ref" in node:
                node = schema["$defs"][node["$ref"].rsplit("/", 1)[-1]]
            else:
                node = next(item for item in node["anyOf"] if item.get("type") != "null")
        if part is None:
            return node
        if isinstance(part, int):
            node = (node.get("prefixItems") or [node.get("items", {})] * (part + 1))[part]
        else:
            keyed = [*node.get("patternProperties", {}).values(), node.get("additionalProperties")]
            node = node.get("properties", {}).get(part) or keyed[0] or {}
    return node


def _reason(error: ErrorDetails, field: dict[str, Any], part: dict[str, Any]) -> str:
    """One error in words: `field` is the schema of the offending field, `part` of its part."""
    kind, ctx, got = error["type"], error.get("ctx") or {}, repr(error["input"])
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        low = field.get("minimum", field.get("exclusiveMinimum"))
        high = field.get("maximum", field.get("exclusiveMaximum"))
        if low is not None and high is not None:
            opening = "(" if "exclusiveMinimum" in field else "["
            return f"{got} is outside {opening}{low}, {high}{')' if 'exclusiveMaximum' in field else ']'}"
        sign = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<"}.get(kind, "<=")
        return f"must be {sign} {next(iter(ctx.values()))}, got {got}"
    if kind == "missing":
        return "required"
    if kind == "unexpected_keyword_argument":
        return f"unknown field (known here: {', '.join(sorted(part.get('properties', {})))})"
    if kind in ("too_short", "too_long") and field.get("minItems") == field.get("maxItems"):
        numbers = all(item.get("type") == "number" for item in field.get("prefixItems", [{}]))
        return f"expected a list of {field['minItems']} {'numbers' if numbers else 'entries'}, got {got}"
    if kind == "too_short":
        return f"expected at least {ctx['min_length']} entries, got {got}"
    if kind == "too_long":
        return f"expected at most {ctx['max_length']} entries, got {got}"
    if kind in ("dataclass_type", "dict_type"):
        return f"expected a mapping of fields, got {got}"
    if kind in ("list_type", "tuple_type"):
        return f"expected a list, got {got}"
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
        text = json.dumps(_nulls_dropped(data, (), nullable))
    except (TypeError, ValueError) as error:  # a YAML date or set: no value of a scenario
        raise ScenarioError(
            f"scenario: only numbers, strings, lists and mappings ({error})"
        ) from None
    try:
        return adapter.validate_json(text)
    except ValidationError as error:
        first = error.errors()[0]
        location = [part for part in first["loc"] if not str(part).startswith("function-")]
        if first["type"] == "missing" and location and isinstance(location[-1], int):
            # A list too short for its fixed length: pydantic reports the first missing entry.
            location.pop()
            first["type"] = "too_short"
        schema = adapter.json_schema()
        field, part = _schema_at(schema, location), _schema_at(schema, location[:-1])
        path = field_path(location) or ""
        if first["type"] == "scenario_field":
            named = str((first.get("ctx") or {})["field"])  # by the part's own check
            path += named if named.startswith("[") or not path else f".{named}"
        raise ScenarioError(f"{path or 'scenario'}: {_reason(first, field, part)}") from None
