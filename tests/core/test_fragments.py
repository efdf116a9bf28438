"""The fragment rule: a leftover proposal that is a piece of an object another proposal shows."""

from __future__ import annotations

import numpy as np

from core.association import fragments
from core.geometry import Proposal
from core.params import AssociationParams
from core.state import SceneState
from tests.core.scenes import run_log, scene_batch, track_events


def proposal(
    label: str, center: tuple[float, ...], extent: tuple[float, ...], pixels: int
) -> Proposal:
    return Proposal(
        label, 0.9, "object", np.array(center), np.array(extent), None, pixels, "f", 0.0, 0.0
    )


def test_a_piece_showing_the_side_the_track_never_saw_is_still_a_piece() -> None:
    # A box the keyframes saw end-on (its stored box is narrow along x), split in two by the
    # capture's view: one half shows the end face, the other the long face along x.
    size = np.array([0.143, 0.2, 0.148])
    whole = proposal("box", (4.475, 6.602, 1.07), (0.04, 0.183, 0.145), 3125)
    piece = proposal("box", (4.586, 6.5, 1.093), (0.235, 0.086, 0.144), 3143)
    pieces = fragments([whole, piece], {0: "trk-1"}, lambda _: size, AssociationParams())
    assert pieces == {1}


def test_two_slim_objects_side_by_side_are_two_objects() -> None:
    # Two bottles 8 cm apart: joined they are twice as wide as one, whichever way it turns.
    size = np.array([0.07, 0.07, 0.25])
    left = proposal("bottle", (1.0, 2.0, 0.9), (0.07, 0.07, 0.25), 900)
    right = proposal("bottle", (1.08, 2.0, 0.9), (0.07, 0.07, 0.25), 880)
    assert fragments([left, right], {0: "trk-1"}, lambda _: size, AssociationParams()) == set()
    # Stacked upright pieces of one bottle (its top and bottom halves) stay one object.
    top = proposal("bottle", (1.0, 2.0, 0.96), (0.07, 0.06, 0.12), 450)
    assert fragments([left, top], {0: "trk-1"}, lambda _: size, AssociationParams()) == {1}


def test_a_mug_beside_one_whose_union_box_grew_is_a_new_object_not_a_piece() -> None:
    # A mug nudged along the wall in steps under the move threshold: its union box (what the
    # visibility gate samples) spans 0.4 m, the mug itself 0.1 m. A second mug 0.35 m from it
    # is sized against the mug, not the grown box: a new hypothesis.
    state = SceneState()
    for i, x in enumerate((0.0, 0.08, 0.16, 0.24, 0.3)):
        state, _ = run_log(state, [scene_batch(f"n{i}", {"mug_1": ((x, 0.1, 2.0), 0.1)}, t=i)])
    (track,) = state.tracks.values()
    assert track.box is not None and track.box[3] - track.box[0] > 0.35
    both = {"mug_1": ((0.3, 0.1, 2.0), 0.1), "mug_2": ((-0.05, 0.1, 2.0), 0.1)}
    _, log = run_log(state, [scene_batch("two", both, t=5.0)])
    assert [e.type for e in track_events(log)].count("add") == 1
