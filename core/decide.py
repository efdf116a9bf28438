"""decide: one semantic update batch -> typed events. Reads as sections 3.2 and 3.3 of the paper."""

from __future__ import annotations

from functools import partial

from core.association import associate, fragments
from core.batch_evidence import BatchEvidence
from core.events import Event
from core.fixture_step import fixture_batch
from core.geometry import Proposal, ground_detection
from core.observation import Batch, Frame
from core.occupancy_evidence import occupancy_evidence
from core.params import Params
from core.rules import PAPER_RULES, UpdateRules
from core.state import SceneState


def decide(
    state: SceneState, batch: Batch, params: Params | None = None, rules: UpdateRules = PAPER_RULES
) -> list[Event]:
    """Events of one batch; pure and deterministic. `params` defaults to the scene's own."""
    params = params or state.params
    evidence = BatchEvidence(state, params, rules)
    evidence.forget_beyond(batch.frames[0].timestamp)
    # 1. Coarse fixtures: the batch's fixture masks add class evidence to the voxel map, which
    #    is queried against the taxonomy, clustered and associated with fixture tracks (3.2, 3.3).
    fixtures = fixture_batch(state, batch, params)
    for track_id, cluster in sorted(fixtures.observed.items()):
        evidence.observe_fixture(track_id, cluster)
    for cluster in fixtures.unexplained:
        evidence.observe_fixture(None, cluster)
    #    A second track of one fixture, inside a confirmed one's footprint, joins it.
    evidence.merged = fixtures.merged
    for frame in batch.frames:
        # 2. Grounded observations: back-project each object mask's valid depth (section 3.2).
        proposals = ground_frame(frame, params)
        # 3. Visibility gate: samples of each stored box that could be in view; a track left
        #    unmatched in a frame that showed it is a visible miss (section 3.3).
        evidence.record_visibility(frame)
        # 4. Dynamic association: class compatibility, 3D distance < 0.8 m, appearance > 0.78,
        #    greedy 1:1, then the unique-class fallback for tracks whose absence is established
        #    (not for a piece of an object a matched proposal shows); removed tracks take part
        #    (section 3.3).
        matches = associate(
            proposals,
            evidence.pool(),
            params.association,
            partial(fragments, proposals, size_of=evidence.extent_of, params=params.association),
        )
        #    A leftover piece of an object another proposal shows (an over-segmented mask) is
        #    set aside, not taken for a new object.
        pieces = fragments(proposals, matches, evidence.extent_of, params.association)
        #    A fine node attached by an inspection capture does not re-enter this front end: a
        #    proposal it explains is set aside too (section 3.3).
        held = {j for j, track_id in matches.items() if evidence.held_by_capture(track_id)}
        for j, proposal in enumerate(proposals):
            if j not in pieces and j not in held:
                evidence.observe(matches.get(j) or evidence.new_track(proposal), proposal)
    # 5. One existence update per track per batch (equation (3)), support parents from
    #    geometry, then lifecycle events.
    head: list[Event] = [fixtures.evidence_event] if fixtures.evidence_event is not None else []
    # 6. The occupancy map A_t: the batch's depth, as free and occupied cells (section 3.2).
    occupancy = occupancy_evidence(batch.frames, params.occupancy)
    head += [occupancy] if occupancy is not None else []
    return [*head, *evidence.events()]


def ground_frame(frame: Frame, params: Params) -> list[Proposal]:
    """Object proposals of one frame; masks with too little valid depth are rejected."""
    proposals = []
    for index, detection in enumerate(frame.detections):
        if detection.kind != "object":
            continue  # fixture masks feed the voxel map instead
        proposal = ground_detection(
            detection,
            frame,
            params.proposal,
            params.visibility.min_range_m,
            params.visibility.max_range_m,
            index,
        )
        if proposal is not None:
            proposals.append(proposal)
    return proposals
