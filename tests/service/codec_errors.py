"""Bodies that must fail: the codec's error, or the schema's errors, for the codec tests."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from api_schema import BatchIn
from codec.observations import InvalidObservation, decode_batch


def decode_error(body: dict[str, Any]) -> InvalidObservation:
    """Decode a body that must fail in the codec (after passing the schema)."""
    batch = BatchIn.model_validate(body)
    with pytest.raises(InvalidObservation) as caught:
        decode_batch(batch)
    return caught.value


def schema_errors(body: dict[str, Any]) -> list[tuple[tuple[str | int, ...], str]]:
    """(location, type) of each pydantic error of a body that must fail the schema."""
    with pytest.raises(ValidationError) as caught:
        BatchIn.model_validate(body)
    return [(tuple(error["loc"]), error["type"]) for error in caught.value.errors()]
