"""Fixture-centered inspection capture (sections 3.2 and 3.4): ground fine objects on one fixture.

One primary view is grounded; alternate views only serve as a retry when the primary does not
show the fixture's support region. They are never fused. Which contract-valid view is the
primary, and whether the views vote on the labels, is `core.sweep`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from core.decisions import TrackDecision
from core.emit import decision_events
from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.events import Event, InspectionRecorded
from core.existence import capture_updates
from core.frontend import associate_capture
from core.geometry import Proposal
from core.lifecycle import capture_decisions
from core.observation import Frame
from core.params import SUPPORT_SLAB_M, Params
from core.state import SceneState, Track
from core.sweep import sweep_proposals
from core.values import InspectionStatus, ViewPose
from core.visibility import Sighting, observable, sample_columns


def support_region_visible(fixture: Track, frame: Frame, params: Params) -> int:
    """How many samples of the fixture's top surface pass the visibility gate in `frame`."""
    top = fixture.center[2] + fixture.extent[2] / 2
    center = np.array([[fixture.center[0], fixture.center[1], top]])
    extent = np.array([[fixture.extent[0], fixture.extent[1], SUPPORT_SLAB_M]])
    return int(sample_columns(center, extent, frame, params.visibility).passed[0])


def decide_inspection(
    state: SceneState,
    capture_id: str,
    fixture_id: str,
    frames: Sequence[Frame],
    fixture_verified: bool | None,
    params: Params | None = None,
    view: ViewPose | None = None,
) -> list[Event]:
    """Children of the fixture (add/confirm/reparent or update) and the capture's ledger entry.

    The capture's view is the one the client names, else the locked view when the fixture is
    the locked target: a failed capture excludes views near it (section 3.4).
    """
    params = params or state.params
    lock = state.plan.lock
    if view is None and lock is not None and lock.fixture_id == fixture_id:
        view = lock.view
    fixture = state.tracks.get(fixture_id)
    if fixture is None:
        raise UnknownTrack(f"fixture {fixture_id!r} does not exist", "fixture_id")
    if fixture.kind != "fixture":
        raise InvalidCommand(f"track {fixture_id!r} is an object, not a fixture", "fixture_id")
    if fixture.lifecycle != "confirmed":
        raise StateConflict(
            f"fixture {fixture_id!r} is {fixture.lifecycle}, not confirmed", "fixture_id"
        )
    # 1. Visibility: the views that show the fixture's support region (contract-valid).
    valid = [
        f
        for f in frames
        if support_region_visible(fixture, f, params) >= params.inspection.min_support_samples
    ]
    outcome: Literal["completed", "support_not_visible", "parent_rejected"] = "completed"
    if fixture_verified is False:
        outcome = "parent_rejected"  # the client's model says this is not the fixture
    elif not valid:
        outcome = "support_not_visible"
    decisions: tuple[TrackDecision, ...] = ()
    children: list[str] = []
    primary = valid[0] if valid else None
    if outcome == "completed":
        # 2. The primary view and its grounded proposals on the fixture; in it, the fine
        #    nodes the ledger holds on the fixture (section 3.4).
        primary, chosen = sweep_proposals(fixture, valid, params)
        held = _held_children(state, fixture, primary, params)
        decisions, children = _attach_children(state, fixture, chosen, held, params)
    attempts = fixture.inspection_attempts + (outcome != "completed")
    status: InspectionStatus | None = (
        "completed"
        if outcome == "completed"
        else ("abandoned" if attempts >= params.inspection.max_attempts else None)
    )
    frame_id = primary.frame_id if primary is not None else (frames[0].frame_id if frames else None)
    record = InspectionRecorded(
        track_id=fixture_id,
        state=fixture.lifecycle,
        frame_id=frame_id,
        capture_id=capture_id,
        fixture_id=fixture_id,
        frames=tuple(f.frame_id for f in frames),
        primary_frame=None if primary is None else primary.frame_id,
        fixture_verified=fixture_verified,
        outcome=outcome,
        children=tuple(children),
        attempts=attempts,
        status=status,
        view=view,
    )
    return [*decision_events(decisions, params), record]


def _attach_children(
    state: SceneState,
    fixture: Track,
    chosen: Sequence[Proposal],
    held: Sequence[tuple[Track, Sighting]],
    params: Params,
) -> tuple[tuple[TrackDecision, ...], list[str]]:
    """The capture's children through the batch's stages from the primary view's proposals
    on this fixture: the frame-level front end, equation (3), then the lifecycle rules, where
    the verified capture stands in for cross-batch confirmation."""
    # 3. Association: the frame-level front end (section 3.3).
    assigned = associate_capture(state, chosen, params)
    children = [track_id for _, track_id in assigned]
    # 4. Existence, equation (3): each child seen, each held fine node it shows and did not find
    #    a visible miss (only a capture speaks of what the capture ledger holds, section 3.3).
    sightings, misses = capture_updates(
        state, [(chosen[j], track_id) for j, track_id in assigned], fixture.track_id, held, params
    )
    # 5. Lifecycle: publication, move, reparent; demotion and removal of the missed.
    return capture_decisions(state, sightings, misses, params), children


def _held_children(
    state: SceneState, fixture: Track, frame: Frame, params: Params
) -> list[tuple[Track, Sighting]]:
    """The fine nodes the capture ledger holds on the fixture that `frame` shows (observable)."""
    held = [
        t
        for t in state.tracks.values()
        if t.capture_id is not None
        and t.lifecycle in ("confirmed", "demoted")
        and t.parent == fixture.track_id
    ]
    if not held:
        return []
    boxes = [_box_of(t) for t in held]
    sightings = sample_columns(
        np.array([c for c, _ in boxes]),
        np.array([e for _, e in boxes]),
        frame,
        params.visibility,
        probes=np.array([t.center for t in held]),
    ).sightings(frame.frame_id)
    return [
        (track, sighting)
        for track, sighting in zip(held, sightings, strict=True)
        if observable(sighting, params.visibility)
    ]


def _box_of(track: Track) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The box the visibility gate samples: the union of its views, else center and extent."""
    if track.box is None:
        return track.center, track.extent
    low, high = track.box[:3], track.box[3:]
    return (
        tuple((a + b) / 2 for a, b in zip(low, high, strict=True)),
        tuple(b - a for a, b in zip(low, high, strict=True)),
    )
