"""The association's distances (core/association.py `_distances`): every track within reach of a
proposal is found, with the distance `np.linalg.norm` gives, to the last bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from core.association import _distances
from core.geometry import Proposal


def proposal_at(center: np.ndarray) -> Proposal:
    return Proposal("mug", 0.9, "object", center, np.full(3, 0.1), None, 100, "f", 0.0, 0.0)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    tracks=st.integers(0, 3000),
    proposals=st.integers(1, 40),
    scale=st.sampled_from([0.5, 3.0, 50.0]),
)
def test_every_track_in_reach_is_found_at_norm_s_distance(
    seed: int, tracks: int, proposals: int, scale: float
) -> None:
    rng = np.random.default_rng(seed)
    centers = rng.normal(0, scale, (tracks, 3))
    points = rng.normal(0, scale, (proposals, 3))
    centers[: min(tracks, proposals)] = points[: min(tracks, proposals)] + 0.8 * np.eye(3)[0]
    reach = 0.8
    found = list(_distances([proposal_at(p) for p in points], centers, reach))
    assert len(found) == proposals
    for point, (rows, distances) in zip(points, found, strict=True):
        expected = np.linalg.norm(centers - point, axis=1)
        assert np.array_equal(distances, expected[rows])
        # No track outside the rows is within reach.
        outside = np.setdiff1d(np.arange(tracks), rows)
        assert not (expected[outside] < reach).any()
