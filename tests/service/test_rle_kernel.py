"""COCO's compressed RLE decoded by the compiled loop (codec/rle.py) against the rule in numpy
array operations it replaced: the same run lengths, or the same refusal with the same reason."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from codec.rle import compressed_rle_counts, compressed_rle_counts_numpy
from core.masks import Mask
from tests.wire_bodies import rle_of


def outcome(decode: object, counts: str) -> tuple[str, list[int]]:
    assert callable(decode)
    try:
        return "runs", decode(counts).tolist()
    except ValueError as error:
        return str(error), []


# Characters of the encoding ('0'..'o'), with the two just outside it and non-ASCII.
ALPHABET = st.sampled_from([chr(c) for c in range(48, 112)] + ["/", "p", "\u00e9"])


@settings(max_examples=400, deadline=None)
@given(st.text(ALPHABET, min_size=0, max_size=40))
def test_any_string_decodes_or_is_refused_as_the_numpy_rule_does(counts: str) -> None:
    assert outcome(compressed_rle_counts, counts) == outcome(compressed_rle_counts_numpy, counts)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_masks_encoded_as_clients_encode_them_give_their_runs_back(
    height: int, width: int, seed: int
) -> None:
    mask = np.random.default_rng(seed).random((height, width)) < 0.4
    counts = rle_of(mask)["counts"]
    runs = compressed_rle_counts(counts)
    assert runs.tolist() == compressed_rle_counts_numpy(counts).tolist()
    assert runs.tolist() == Mask.from_array(mask).runs.tolist()


@pytest.mark.parametrize(
    ("counts", "reason"),
    [
        ("", "empty"),
        ("0p", "outside '0'..'o'"),
        ("0`", "ends in the middle of a value"),
        ("``````0", "too large"),
        ("0@", "negative run length"),
    ],
)
def test_each_fault_is_named(counts: str, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        compressed_rle_counts(counts)
