"""Fixture-centered inspection capture (sections 3.2 and 3.4): ground fine objects on one fixture.

One primary view is grounded; alternate views only serve as a retry when the primary does not
show the fixture's support region. They are never fused.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Literal

import numpy as np

from core.association import associate, fragments
from core.batch_evidence import BatchEvidence
from core.decide import ground_frame
from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.events import Event, InspectionRecorded, ObjectAdded, ObjectObserved, TrackConfirmed
from core.geometry import Proposal
from core.masks import Mask, mask_iou
from core.observation import Frame
from core.params import Params
from core.state import SceneState, Track
from core.support import SupportSurface, support_of
from core.transitions import added_object, confirmed, observed_object, visible_miss
from core.values import InspectionStatus, ViewPose, vec3
from core.visibility import observable, samples_passed

SUPPORT_SLAB_M = 0.02  # thickness of the sampled support region (the fixture's top surface)


def support_region_visible(fixture: Track, frame: Frame, params: Params) -> int:
    """How many samples of the fixture's top surface pass the visibility gate in `frame`."""
    top = fixture.center[2] + fixture.extent[2] / 2
    center = np.array([[fixture.center[0], fixture.center[1], top]])
    extent = np.array([[fixture.extent[0], fixture.extent[1], SUPPORT_SLAB_M]])
    return samples_passed(center, extent, frame, params.visibility)[0].passed


def suppress(proposals: Sequence[Proposal], masks: Sequence[Mask], params: Params) -> list[int]:
    """Indices kept by same-class NMS and cross-class overlap suppression (by mask IoU)."""
    order = sorted(range(len(proposals)), key=lambda i: (-proposals[i].score, i))
    kept: list[int] = []
    for i in order:
        clash = False
        for k in kept:
            iou = mask_iou(masks[i], masks[k])
            limit = (
                params.inspection.nms_mask_iou
                if proposals[i].label == proposals[k].label
                else params.inspection.cross_class_mask_iou
            )
            if iou > limit:
                clash = True
                break
        if not clash:
            kept.append(i)
    return sorted(kept)


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
    primary = next(
        (
            f
            for f in frames
            if support_region_visible(fixture, f, params) >= params.inspection.min_support_samples
        ),
        None,
    )
    outcome: Literal["completed", "support_not_visible", "parent_rejected"] = "completed"
    if fixture_verified is False:
        outcome = "parent_rejected"  # the client's model says this is not the fixture
    elif primary is None:
        outcome = "support_not_visible"
    events: list[Event] = []
    children: list[str] = []
    if outcome == "completed":
        assert primary is not None
        events, children = _attach_children(state, fixture, primary, params)
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
    return [*events, record]


def _attach_children(
    state: SceneState, fixture: Track, frame: Frame, params: Params
) -> tuple[list[Event], list[str]]:
    """Ground the primary view, keep what lies on this fixture, and attach it as children."""
    surface = [SupportSurface(fixture.track_id, fixture.center, fixture.extent)]
    proposals = ground_frame(frame, params)
    masks = [frame.detections[p.detection_index].mask for p in proposals]
    kept = [
        i
        for i in suppress(proposals, masks, params)
        if support_of(proposals[i].center, proposals[i].bottom_z, surface, params.fixtures)
        == fixture.track_id
    ]
    evidence = BatchEvidence(state, params)
    chosen = [proposals[i] for i in kept]
    matches = associate(
        chosen,
        evidence.pool(),
        params.association,
        partial(fragments, chosen, size_of=evidence.extent_of, params=params.association),
    )
    # A piece of an object another proposal of the view shows (an over-segmented mask) is not a
    # second child, as in the frame-level front end.
    pieces = fragments(chosen, matches, evidence.extent_of, params.association)
    events: list[Event] = []
    children: list[str] = []
    next_number = state.next_track_number
    for j, proposal in enumerate(chosen):
        if j in pieces:
            continue
        parents = [fixture.track_id]
        track_id = matches.get(j)
        if track_id is not None and state.tracks[track_id].kind == "object":
            observed = observed_object(state.tracks[track_id], [proposal], parents, params)
            update = observed[0]
            assert isinstance(update, ObjectObserved)
            if update.state != "confirmed" and not any(
                isinstance(e, TrackConfirmed) for e in observed
            ):
                # A child matched a hypothesis or a removed track: the verified capture publishes
                # it, as it does a new child (a child listed as completed is always in the graph).
                observed.insert(
                    1,
                    confirmed(
                        track_id,
                        frame.frame_id,
                        update.p_exist,
                        vec3(proposal.center),
                        update.batches_observed,
                        reason="inspection",
                    ),
                )
            events += observed
        else:
            track_id = f"trk-{next_number:06d}"
            next_number += 1
            added = added_object(track_id, [proposal], parents, params)
            if any(isinstance(e, TrackConfirmed) for e in added):  # published on sight already
                events += added
            else:
                # A verified capture stands in for cross-batch confirmation (section 3.2).
                first = added[0]
                assert isinstance(first, ObjectAdded)
                confirm = confirmed(
                    track_id,
                    frame.frame_id,
                    first.p_exist,
                    vec3(proposal.center),
                    1,
                    reason="inspection",
                )
                events += [first, confirm, *added[1:]]
        children.append(track_id)
    return [*events, *_unseen_children(state, fixture, frame, set(children), params)], children


def _unseen_children(
    state: SceneState, fixture: Track, frame: Frame, found: set[str], params: Params
) -> list[Event]:
    """Visible misses of the fixture's fine nodes this capture shows and did not find: only a
    capture speaks of what the capture ledger holds (section 3.3)."""
    held = [
        t
        for t in state.tracks.values()
        if t.capture_id is not None
        and t.lifecycle in ("confirmed", "demoted")
        and t.parent == fixture.track_id
        and t.track_id not in found
    ]
    if not held:
        return []
    boxes = [_box_of(t) for t in held]
    sightings = samples_passed(
        np.array([c for c, _ in boxes]),
        np.array([e for _, e in boxes]),
        frame,
        params.visibility,
        probes=np.array([t.center for t in held]),
    )
    events: list[Event] = []
    for track, sighting in zip(held, sightings, strict=True):
        if observable(sighting, params.visibility):
            events += visible_miss(track, sighting.passed, frame.frame_id, params)
    return events


def _box_of(track: Track) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The box the visibility gate samples: the union of its views, else center and extent."""
    if track.box is None:
        return track.center, track.extent
    low, high = track.box[:3], track.box[3:]
    return (
        tuple((a + b) / 2 for a, b in zip(low, high, strict=True)),
        tuple(b - a for a, b in zip(low, high, strict=True)),
    )
