"""The fold's unrolled arithmetic gives the very floats of the formulas it replaced."""

from __future__ import annotations

import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from core.evolve import _box
from core.state import Track
from core.values import Vec3

coordinate = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 0.5, -0.5]),
)
vec3 = st.tuples(coordinate, coordinate, coordinate)


def _formula(boxes: list[tuple[Vec3, Vec3]]) -> tuple[float, ...]:
    """The union as written before: min and max over the boxes, axis by axis."""
    low = [min(c[i] - e[i] / 2 for c, e in boxes) for i in range(3)]
    high = [max(c[i] + e[i] / 2 for c, e in boxes) for i in range(3)]
    return (*low, *high)


def _bits(values: tuple[float, ...]) -> bytes:
    return struct.pack(f"<{len(values)}d", *values)  # tells -0.0 from 0.0


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(vec3, vec3), min_size=1, max_size=4))
def test_box_equals_the_formula_bit_for_bit(boxes: list[tuple[Vec3, Vec3]]) -> None:
    assert _bits(_box(boxes)) == _bits(_formula(boxes))


def _track(embedding_sum: tuple[float, ...] | None = None) -> Track:
    return Track(
        track_id="trk-000001",
        kind="object",
        lifecycle="tentative",
        class_evidence={"mug": 1.0},
        existence_logodds=0.5,
        center=(1.0, 2.0, 3.0),
        extent=(0.1, 0.1, 0.1),
        recent_centers=((1.0, 2.0, 3.0),),
        embedding_sum=embedding_sum,
        embedding_count=0 if embedding_sum is None else 2,
    )


def test_evolved_copies_the_fields_and_drops_the_cached_label() -> None:
    track = _track()
    assert track.label == "mug" and "label" in track.__dict__
    changed = track.evolved(class_evidence={"book": 2.0, "mug": 1.0})
    assert "label" not in changed.__dict__ and changed.label == "book"
    assert changed.__dict__.keys() - {"label"} == track.__dict__.keys() - {"label"}
    assert changed.center == track.center and changed.track_id == track.track_id
    same = track.evolved()
    assert same == track and "label" not in same.__dict__


def test_the_appearance_is_computed_once_read_only_and_anew_for_a_changed_sum() -> None:
    track = _track(embedding_sum=(3.0, 4.0))
    unit = track.embedding()
    assert unit is not None and unit.tolist() == [0.6, 0.8]
    assert track.embedding() is unit and not unit.flags.writeable
    changed = track.evolved(embedding_sum=(0.0, 2.0))
    again = changed.embedding()
    assert again is not None and again.tolist() == [0.0, 1.0]
    assert track.evolved(embedding_sum=(0.0, 0.0)).embedding() is None  # no direction
    assert track.evolved(embedding_sum=None).embedding() is None
