"""The views of one inspection sweep (section 3.4): which is the primary, and what it grounds.

The paper grounds "one contract-valid primary view" of the fixed-base sweep and uses the
alternates for retry, never fusing masks, point clouds or 3D proposals across them. A view is
contract-valid when it shows the fixture's support region. Two extensions read the alternates
without fusing their geometry:

- `InspectionParams.primary_view` "most_grounded": the primary is the valid view whose
  proposals on the fixture stand for the most objects another valid view corroborates, then
  the most objects, not the first (the detector missed an object in the first view and
  reported it in the next);
- `InspectionParams.sweep_class_votes`: each proposal of the primary takes the label most of the
  valid views give the object there (a mug labelled cup in one view of three). Its position,
  extent, mask and appearance stay the primary's.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from core.geometry import Proposal
from core.grounding import ground_frame
from core.masks import Mask, mask_iou
from core.observation import Frame
from core.params import Params
from core.state import Track
from core.support import SupportSurface, parents_of


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


def on_fixture(fixture: Track, frame: Frame, params: Params) -> list[Proposal]:
    """The frame's grounded proposals after same-class NMS and cross-class suppression that
    rest on the fixture."""
    surface = [SupportSurface(fixture.track_id, fixture.center, fixture.extent)]
    proposals = ground_frame(frame, params)
    masks = [frame.detections[p.detection_index].mask for p in proposals]
    kept = [proposals[i] for i in suppress(proposals, masks, params)]
    parents = parents_of(kept, surface, params.fixtures)
    return [p for p, parent in zip(kept, parents, strict=True) if parent == fixture.track_id]


def sweep_proposals(
    fixture: Track, valid: Sequence[Frame], params: Params
) -> tuple[Frame, list[Proposal]]:
    """The primary view among the valid ones (`primary_view`) and its proposals on the fixture,
    labelled by the views' votes with `sweep_class_votes`."""
    settings = params.inspection
    if settings.primary_view == "first" and not settings.sweep_class_votes:
        return valid[0], on_fixture(fixture, valid[0], params)
    grounded = [(frame, on_fixture(fixture, frame, params)) for frame in valid]
    index = 0
    if settings.primary_view == "most_grounded":
        views = [proposals for _, proposals in grounded]
        scores = [view_score(p, views[:i] + views[i + 1 :]) for i, p in enumerate(views)]
        index = scores.index(max(scores))  # the first of equals
    primary, chosen = grounded[index]
    if settings.sweep_class_votes:
        alternates = [proposals for k, (_, proposals) in enumerate(grounded) if k != index]
        chosen = class_votes(chosen, alternates)
    return primary, chosen


def _touch(a: Proposal, b: Proposal) -> bool:
    return bool(np.all(np.abs(a.center - b.center) <= (a.extent + b.extent) / 2))


def view_score(
    proposals: Sequence[Proposal], others: Sequence[Sequence[Proposal]]
) -> tuple[int, int]:
    """(objects another valid view corroborates, objects) of one view's proposals.

    Same-class proposals whose 3D boxes touch are one object: a detector's mask split in two
    halves would otherwise make a view count double, and the view be chosen for its split. An
    object is corroborated when a proposal of another view (`others`), of any label, touches
    one of its proposals: a false positive of one view is not seen again from a few degrees
    away, and counted, the view that happened to have the most of them would win.
    """
    if not proposals:
        return 0, 0
    same = np.array([[a.label == b.label and _touch(a, b) for b in proposals] for a in proposals])
    _, group = connected_components(csr_matrix(same), directed=False)
    seen = np.array([any(_touch(p, o) for view in others for o in view) for p in proposals])
    return len(set(group[seen].tolist())), len(set(group.tolist()))


def class_votes(
    chosen: Sequence[Proposal], alternates: Sequence[Sequence[Proposal]]
) -> list[Proposal]:
    """The primary's proposals, each labelled by the majority of the views that show it.

    In each alternate view, a proposal whose 3D box touches a primary proposal's (whatever its
    label) votes for that one, the nearest centre if it touches several. The label most votes
    name wins, the primary's own on ties; a proposal relabelled takes the label, score and class
    scores of the first alternate that named the winner.
    """
    voters: list[list[Proposal]] = [[] for _ in chosen]
    for view in alternates:
        for other in view:
            touching = [i for i, p in enumerate(chosen) if _touch(p, other)]
            if touching:
                nearest = min(
                    touching, key=lambda i: float(np.linalg.norm(chosen[i].center - other.center))
                )
                voters[nearest].append(other)
    voted = []
    for proposal, others in zip(chosen, voters, strict=True):
        tally = Counter([proposal.label, *(o.label for o in others)])
        top = max(tally.values())
        if tally[proposal.label] == top:
            voted.append(proposal)
            continue
        winner = next(o for o in others if tally[o.label] == top)
        voted.append(
            replace(
                proposal,
                label=winner.label,
                score=winner.score,
                class_scores=winner.class_scores,
            )
        )
    return voted
