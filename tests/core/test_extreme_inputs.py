"""Finite but extreme observations, at the edges of what the service admits, never put NaN or
infinity into an event, and the log they make replays to the live state."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import orjson
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.decide import decide
from core.event_records import event_from_record, event_to_record, non_finite_field
from core.events import Event, SceneCreated
from core.evolve import evolve, fold
from core.masks import Mask
from core.observation import Batch, Detection, DetectionKind, Frame, Intrinsics
from core.params import Params
from core.state import SceneState

# The edges of the wire schema and the codec (api_schema/requests.py, codec/observations.py).
FOCAL = st.one_of(st.sampled_from([1.0, 100_000.0, 20.0]), st.floats(1.0, 100_000.0))
TRANSLATION = st.one_of(st.sampled_from([-10_000.0, 10_000.0, 0.0]), st.floats(-10_000.0, 10_000.0))
DEPTH = st.one_of(
    st.sampled_from([0.0, 1e-30, 0.3, 2.0, 6.0, 65_535.0, 2.0**127]),
    st.floats(0.0, 2.0**127, width=32),
)
EMBEDDING = st.floats(-1e6, 1e6)
SCORE = st.floats(-1.0, 1.0)
WIDTH, HEIGHT = 24, 16


@st.composite
def frames(draw: st.DrawFn, index: int) -> Frame:
    angle = draw(st.floats(-np.pi, np.pi))
    pose = np.eye(4)
    pose[:3, :3] = [
        [np.cos(angle), 0.0, np.sin(angle)],
        [0.0, 1.0, 0.0],
        [-np.sin(angle), 0.0, np.cos(angle)],
    ]
    pose[:3, 3] = [draw(TRANSLATION) for _ in range(3)]
    intrinsics = Intrinsics(
        width=WIDTH,
        height=HEIGHT,
        fx=draw(FOCAL),
        fy=draw(FOCAL),
        cx=draw(st.floats(-WIDTH, 2 * WIDTH)),
        cy=draw(st.floats(-HEIGHT, 2 * HEIGHT)),
    )
    depth = np.full((HEIGHT, WIDTH), draw(DEPTH), dtype=np.float32)
    depth[: HEIGHT // 2] = draw(DEPTH)
    detections = []
    for _ in range(draw(st.integers(0, 3))):
        mask = np.zeros((HEIGHT, WIDTH), dtype=bool)
        top, left = draw(st.integers(0, HEIGHT - 1)), draw(st.integers(0, WIDTH - 1))
        mask[top:, left:] = True
        kind: DetectionKind = draw(st.sampled_from(["object", "fixture"]))
        scores = {"table": draw(SCORE), "desk": draw(SCORE)} if kind == "fixture" else None
        embedding = np.array([draw(EMBEDDING) for _ in range(4)]) if draw(st.booleans()) else None
        label = "table" if kind == "fixture" else draw(st.sampled_from(["mug", "cup"]))
        detections.append(
            Detection(label, draw(st.floats(0, 1)), kind, Mask.from_array(mask), embedding, scores)
        )
    return Frame(
        f"f{index}",
        draw(st.floats(-1e11, 1e11)),
        intrinsics,
        pose,
        depth,
        tuple(detections),
    )


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_extreme_finite_inputs_make_only_finite_replayable_events(data: st.DataObject) -> None:
    params = Params.from_dict(
        {"proposal": {"min_valid_depth_pixels": 1}, "fixtures": {"mask_pixel_stride": 1}}
    )
    created = SceneCreated(name="extreme", params=params.to_dict())
    state = evolve(SceneState(), created)
    log: list[Event] = [created]
    seen = data.draw(frames(0))
    for index in range(data.draw(st.integers(1, 6))):
        # The same view again (updates), the view with nothing detected (visible misses), or
        # another view.
        again = data.draw(st.sampled_from(["same", "blind", "new"]))
        if again == "new":
            seen = data.draw(frames(index))
        view = seen if again != "blind" else replace(seen, detections=())
        batch = Batch(f"b{index}", (replace(view, frame_id=f"f{index}"),))
        events = decide(state, batch)
        for event in events:
            record = event_to_record(event)
            assert non_finite_field(record["details"]) is None, record
        state = fold(state, events)
        log += events
    stored = [orjson.loads(orjson.dumps(event_to_record(event))) for event in log]
    replayed = fold(SceneState(), (event_from_record(record) for record in stored))
    assert replayed.to_dict() == state.to_dict()


def _reference_non_finite(value: object, path: str = "details") -> str | None:
    """The first NaN or infinity, found by walking every number (what non_finite_field must say)."""
    if isinstance(value, float):
        return None if np.isfinite(value) else path
    if isinstance(value, dict):
        for key, item in value.items():
            found = _reference_non_finite(item, f"{path}.{key}")
            if found is not None:
                return found
    if isinstance(value, list | tuple):
        for index, item in enumerate(value):
            found = _reference_non_finite(item, f"{path}[{index}]")
            if found is not None:
                return found
    return None


JSON_LEAVES = st.one_of(
    st.floats(),  # NaN and both infinities included
    st.sampled_from([1e308, -1e308, float("nan"), float("inf"), 0.0]),  # sums that overflow
    st.integers(-(10**400), 10**400),  # ints too large for a float
    st.booleans(),
    st.none(),
    st.text(max_size=3),
)
JSON_VALUES = st.recursive(
    JSON_LEAVES,
    lambda children: st.one_of(
        st.lists(children, max_size=6),
        st.lists(children, max_size=6).map(tuple),
        st.dictionaries(st.text(max_size=3), children, max_size=4),
    ),
    max_leaves=30,
)


@given(JSON_VALUES)
def test_non_finite_field_names_the_first_non_finite_number_as_a_full_walk_does(
    value: object,
) -> None:
    assert non_finite_field(value) == _reference_non_finite(value)


def test_non_finite_field_sees_through_a_finite_sum_that_overflows_and_numpy_floats() -> None:
    assert non_finite_field({"a": [1e308, 1e308]}) is None
    assert non_finite_field({"a": [1e308, 1e308, float("nan")]}) == "details.a[2]"
    assert non_finite_field({"a": [1.0, float("inf"), -float("inf")]}) == "details.a[1]"
    assert non_finite_field({"a": [{"b": np.float64("nan")}]}) == "details.a[0].b"
    assert non_finite_field({"a": [10**400, 1.5]}) is None
