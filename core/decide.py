"""decide: one semantic update batch -> typed events. Reads as sections 3.2 and 3.3 of the paper.

Each step is one call into one stage and returns an immutable result the next steps take; the
last step turns the decisions into events.
"""

from __future__ import annotations

from core.emit import batch_events
from core.events import Event
from core.existence import existence_updates
from core.fixture_step import fixture_batch
from core.frontend import associate_batch
from core.grounding import ground_frames
from core.lifecycle import lifecycle_decisions
from core.observation import Batch
from core.occupancy_evidence import occupancy_evidence
from core.params import Params
from core.rules import DEFAULT_RULES, UpdateRules
from core.state import SceneState
from core.support import support_parents
from core.visibility import batch_visibility


def decide(
    state: SceneState,
    batch: Batch,
    params: Params | None = None,
    rules: UpdateRules = DEFAULT_RULES,
) -> list[Event]:
    """Events of one batch; pure and deterministic. `params` defaults to the scene's own."""
    params = params or state.params
    first, last = batch.frames[0], batch.frames[-1]
    # 1. Coarse fixtures: the batch's fixture masks add class evidence to the voxel map, which
    #    is queried against the taxonomy, clustered by DBSCAN and associated with fixture
    #    tracks by class, planar proximity, footprint coverage and IoU (sections 3.2, 3.3).
    fixtures = fixture_batch(state, batch, params)
    # 2. Grounded observations: each object mask's valid depth, back-projected through (K, T),
    #    with a robust median center (section 3.2).
    proposals = ground_frames(batch.frames, params)
    # 3. Visibility gate V_i(t) of equation (3): samples of each stored box in range, inside
    #    the image, with valid depth in a 5x5 window and d_meas + 0.15 m >= d_expected; at
    #    least two must pass (section 3.3). Before association: the fallback lends only an
    #    identity whose absence is established, which this batch's views may establish.
    visibility = batch_visibility(state, batch.frames, params, rules)
    # 4. Association, frame by frame: class compatibility, 3D distance < 0.8 m, appearance
    #    cosine > 0.78, greedy 1:1, then the unique-class fallback for tracks whose absence is
    #    established; then re-identified objects and second tracks of one object (section 3.3).
    association = associate_batch(
        state, fixtures, proposals, visibility, first.timestamp, params, rules
    )
    # 5. Support parents from geometry: the fixture top each sighted object rests on (p_parent).
    parents = support_parents(
        state, association.fixtures, association.merged_fixtures, association.observations, params
    )
    # 6. Existence, equation (3), once per track: l_t = l_{t-1} + eta_o O + eta_c K
    #    - eta_m U V - eta_r R, with the fused centers and appearance (section 3.3).
    updates = existence_updates(
        state, association, parents, visibility, last.frame_id, last.timestamp, params
    )
    # 7. Lifecycle: confirm (cross-batch, p_exist >= 0.72), move (>= 0.35 m), reparent,
    #    demote (< 0.30), remove (<= 0.12 after three visible misses), retire (section 3.3).
    decisions = lifecycle_decisions(
        state, association, updates, last.frame_id, last.timestamp, params, rules.removal
    )
    # 8. The occupancy map A_t: the batch's depth as free and occupied cells (section 3.2).
    occupancy = occupancy_evidence(batch.frames, params.occupancy)
    # 9. Audit events: the evidence, then each track's update and transitions.
    return batch_events(fixtures.evidence_event, occupancy, decisions, params)
