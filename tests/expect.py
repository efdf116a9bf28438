"""Expectations that also narrow types for mypy."""

from __future__ import annotations

from typing import TypeVar

T = TypeVar("T")


def present(value: T | None) -> T:
    """`value`, which the test expects not to be None."""
    assert value is not None
    return value
