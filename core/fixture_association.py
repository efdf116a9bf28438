"""Coarse fixture association (section 3.3, "Type-specific association"): same-class planar
proximity, expanded-footprint coverage and footprint IoU, greedy by planar distance; a strictly
contained residual cluster attaches to an already matched fixture."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.fixtures import FixtureProposal, Footprint
from core.params import FixtureParams


def footprint_of(center: Sequence[float], extent: Sequence[float], grow: float = 0.0) -> Footprint:
    """Planar box of a stored fixture, grown by `grow` on every side."""
    return (
        center[0] - extent[0] / 2 - grow,
        center[1] - extent[1] / 2 - grow,
        center[0] + extent[0] / 2 + grow,
        center[1] + extent[1] / 2 + grow,
    )


def overlap_area(a: Footprint, b: Footprint) -> float:
    """Area of the intersection of two planar boxes."""
    width = min(a[2], b[2]) - max(a[0], b[0])
    height = min(a[3], b[3]) - max(a[1], b[1])
    return max(0.0, width) * max(0.0, height)


def area(box: Footprint) -> float:
    """Area of a planar box."""
    return max(0.0, box[2] - box[0]) * max(0.0, box[3] - box[1])


def footprint_iou(a: Footprint, b: Footprint) -> float:
    """Intersection over union of two planar boxes."""
    shared = overlap_area(a, b)
    return shared / max(area(a) + area(b) - shared, 1e-9)


@dataclass(frozen=True)
class FixtureTrackView:
    """What fixture association needs of a track."""

    track_id: str
    label: str
    center: tuple[float, float, float]
    extent: tuple[float, float, float]


def eligible_distance(
    track: FixtureTrackView, proposal: FixtureProposal, params: FixtureParams
) -> float | None:
    """The pair's planar distance when it is eligible: the same class, under the distance gate,
    and the proposal mostly inside the track's expanded footprint or with enough IoU."""
    if not compatible(track.label, proposal, params):
        return None
    distance = float(
        np.hypot(track.center[0] - proposal.center[0], track.center[1] - proposal.center[1])
    )
    if distance >= params.max_planar_distance_m:
        return None
    box = proposal.footprint
    stored = footprint_of(track.center, track.extent)
    grown = footprint_of(track.center, track.extent, params.footprint_expand_m)
    coverage = overlap_area(box, grown) / max(area(box), 1e-9)
    iou = footprint_iou(box, stored)
    if coverage >= params.min_expanded_coverage or iou >= params.min_footprint_iou:
        return distance
    return None


def absorbs(track: FixtureTrackView, proposal: FixtureProposal, params: FixtureParams) -> bool:
    """A residual proposal of a compatible class lies (mostly) inside the matched track's
    expanded footprint."""
    box = proposal.footprint
    grown = footprint_of(track.center, track.extent, params.footprint_expand_m)
    return compatible(track.label, proposal, params) and overlap_area(
        box, grown
    ) >= params.residual_containment * area(box)


def holds(track: FixtureTrackView, other: FixtureTrackView, params: FixtureParams) -> bool:
    """`other`'s footprint lies (mostly) inside `track`'s expanded footprint, as a residual
    cluster the track absorbs does: a second hypothesis of the same fixture."""
    box = footprint_of(other.center, other.extent)
    grown = footprint_of(track.center, track.extent, params.footprint_expand_m)
    return overlap_area(box, grown) >= params.residual_containment * max(area(box), 1e-9)


def same_place(track: FixtureTrackView, other: FixtureTrackView, params: FixtureParams) -> bool:
    """The two footprints overlap by `same_place_min_iou` and their tops lie within
    `same_place_max_top_gap_m`: one fixture, whatever classes its two tracks were given."""
    if params.same_place_min_iou >= 1.0:
        return False
    iou = footprint_iou(
        footprint_of(track.center, track.extent), footprint_of(other.center, other.extent)
    )
    top = track.center[2] + track.extent[2] / 2
    top_other = other.center[2] + other.extent[2] / 2
    return (
        iou >= params.same_place_min_iou and abs(top - top_other) <= params.same_place_max_top_gap_m
    )


def associate_fixtures(
    proposals: Sequence[FixtureProposal], tracks: Sequence[FixtureTrackView], params: FixtureParams
) -> tuple[dict[int, str], dict[int, str]]:
    """(matches, absorbed): proposal index -> track id, greedy by planar distance.

    A pair is eligible with the same class, planar distance under the gate, and either the
    proposal mostly inside the track's expanded footprint or enough footprint IoU. A residual
    proposal strictly contained in an already matched track is absorbed by it.
    """
    pairs: list[tuple[float, str, int]] = []
    # Only pairs under the distance gate can be eligible: found for all pairs at once (with a
    # hair of slack), then each one's distance computed and gated as before.
    near = np.zeros((len(proposals), len(tracks)), dtype=bool)
    if proposals and tracks:
        centers = np.array([p.center[:2] for p in proposals], dtype=np.float64)
        track_centers = np.array([t.center[:2] for t in tracks], dtype=np.float64)
        gap = track_centers[None, :, :] - centers[:, None, :]
        near = np.hypot(gap[..., 0], gap[..., 1]) < params.max_planar_distance_m + 1e-6
    for j in np.flatnonzero(near.any(axis=1)).tolist():
        proposal = proposals[j]
        for k in np.flatnonzero(near[j]).tolist():
            distance = eligible_distance(tracks[k], proposal, params)
            if distance is not None:
                pairs.append((distance, tracks[k].track_id, j))
    matches: dict[int, str] = {}
    used: set[str] = set()
    for _distance, track_id, j in sorted(pairs):
        if j in matches or track_id in used:
            continue
        matches[j] = track_id
        used.add(track_id)
    absorbed: dict[int, str] = {}
    by_id = {track.track_id: track for track in tracks}
    matched = [by_id[track_id] for track_id in sorted(used)]
    # A proposal of positive area can be absorbed only by a track whose grown footprint it
    # meets: found for all pairs at once (with a hair of slack), then checked as before.
    meets = np.ones((len(proposals), len(matched)), dtype=bool)
    if proposals and matched and params.residual_containment > 0:
        boxes = np.array([p.footprint for p in proposals], dtype=np.float64)
        grown_boxes = np.array(
            [footprint_of(t.center, t.extent, params.footprint_expand_m) for t in matched],
            dtype=np.float64,
        )
        slack = 1e-6
        meets = (
            (boxes[:, None, 0] < grown_boxes[None, :, 2] + slack)
            & (grown_boxes[None, :, 0] < boxes[:, None, 2] + slack)
            & (boxes[:, None, 1] < grown_boxes[None, :, 3] + slack)
            & (grown_boxes[None, :, 1] < boxes[:, None, 3] + slack)
        )
        flat = (boxes[:, 2] - boxes[:, 0] <= 0) | (boxes[:, 3] - boxes[:, 1] <= 0)
        meets[flat] = True  # no area: contained in anything
    for j in np.flatnonzero(meets.any(axis=1)).tolist():
        if j in matches:
            continue
        proposal = proposals[j]
        for k in np.flatnonzero(meets[j]).tolist():
            if absorbs(matched[k], proposal, params):
                absorbed[j] = matched[k].track_id
                break
    return matches, absorbed


def compatible(track_label: str, proposal: FixtureProposal, params: FixtureParams) -> bool:
    """Class agreement of a fixture track and a cluster: the same top class, or the track's
    class within `compatible_class_margin` of the cluster's best mean similarity. A desk/table
    the segmenter cannot tell apart stays one fixture whose class evidence says so (and the
    consensus gate then asks for a verdict), instead of two fixtures in one place."""
    if track_label == proposal.label:
        return True
    rival = proposal.class_means.get(track_label)
    best = proposal.class_means.get(proposal.label)
    return rival is not None and best is not None and best - rival <= params.compatible_class_margin
