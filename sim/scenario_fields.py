"""Typed field access for scenario files: every error names the field it is about."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from pbdag_errors import Refused

T = TypeVar("T")
_REQUIRED: Any = object()


class ScenarioError(Refused, ValueError):
    """A scenario file that cannot be used; the message starts with the offending field."""


class Section:
    """One mapping of the file: typed field access plus a check for unknown (misspelt) fields."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, Mapping):
            raise ScenarioError(f"{where or 'scenario'}: expected a mapping of fields")
        self.data, self.where, self.used = data, where, set[str]()

    def path(self, key: str) -> str:
        """Dotted name of a field, as error messages spell it."""
        return f"{self.where}.{key}" if self.where else key

    def get(self, key: str, parse: Callable[[Any, str], T], default: Any = _REQUIRED) -> T:
        """The parsed field; `null` counts as absent."""
        self.used.add(key)
        value = self.data.get(key)
        if value is None:
            if default is _REQUIRED:
                raise ScenarioError(f"{self.path(key)}: required")
            return default  # type: ignore[no-any-return]
        return parse(value, self.path(key))

    def finish(self) -> None:
        """Fail on fields nobody asked for: a typo must not silently fall back to a default."""
        unknown = sorted(str(key) for key in self.data if str(key) not in self.used)
        if unknown:
            known = ", ".join(sorted(self.used))
            raise ScenarioError(f"{self.path(unknown[0])}: unknown field (known here: {known})")


def number(value: Any, where: str, low: float | None = None, high: float | None = None) -> float:
    """A finite number within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"{where}: expected a finite number, got {value!r}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ScenarioError(f"{where}: {value} is outside [{low}, {high}]")
    return float(value)


def positive(value: Any, where: str, *, integer: bool = False, zero: bool = False) -> float:
    """A number > 0 (>= 0 with `zero`), optionally an integer."""
    if integer and (isinstance(value, bool) or not isinstance(value, int)):
        raise ScenarioError(f"{where}: expected an integer, got {value!r}")
    parsed = number(value, where)
    if parsed < 0 or (parsed == 0 and not zero):
        raise ScenarioError(f"{where}: must be {'>= 0' if zero else '> 0'}, got {value!r}")
    return parsed


def count(value: Any, where: str) -> int:
    """A non-negative integer."""
    return int(positive(value, where, integer=True, zero=True))


def fraction(value: Any, where: str) -> float:
    """A probability in [0, 1]."""
    return number(value, where, 0.0, 1.0)


def text(value: Any, where: str) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise ScenarioError(f"{where}: expected a non-empty string, got {value!r}")
    return value


def vector(value: Any, where: str, length: int, *, positive_only: bool = False) -> Any:
    """A list of `length` numbers as a float tuple."""
    if not isinstance(value, list | tuple) or len(value) != length:
        raise ScenarioError(f"{where}: expected a list of {length} numbers, got {value!r}")
    items = tuple(number(item, f"{where}[{index}]") for index, item in enumerate(value))
    if positive_only and min(items) <= 0:
        raise ScenarioError(f"{where}: every entry must be > 0, got {value!r}")
    return items


def sequence(value: Any, where: str, parse: Callable[[Any, str], T]) -> list[T]:
    """A list whose items each parse with `parse`."""
    if not isinstance(value, list):
        raise ScenarioError(f"{where}: expected a list")
    return [parse(item, f"{where}[{index}]") for index, item in enumerate(value)]


def boolean(value: Any, where: str) -> bool:
    """A YAML true/false."""
    if not isinstance(value, bool):
        raise ScenarioError(f"{where}: expected true or false, got {value!r}")
    return value
