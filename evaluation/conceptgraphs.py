"""ConceptGraphs' map maintenance as a runner hook: detection-count filter, periodic merge, pruning.

Follows concept-graphs/concept-graphs, `conceptgraph/slam/utils.py` (`filter_objects`,
`merge_overlap_objects`) with the settings of `conceptgraph/hydra_configs/base_mapping.yaml`
(obj_min_detections 3, merge_overlap_thresh 0.7, merge_visual_sim_thresh 0.7,
merge_text_sim_thresh 0.7) run at the interval of `rerun_realtime_mapping.yaml` (merge and filter
every 5 processed frames; our processed unit is a batch of 2 frames, hence every 10 frames).
ConceptGraphs measures overlap as the share of one object's points lying near the other's; our
tracks are boxes, so the share of one box's volume inside the other stands in for it. Its text
similarity compares class-name embeddings; the same class label stands in for "above 0.7".
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from core.events import Event, ObjectAdded, ObjectObserved, TrackRemoved
from core.state import SceneState, Track

MIN_DETECTIONS = 3  # obj_min_detections: fewer and the object is not in the map
MERGE_OVERLAP = 0.7  # merge_overlap_thresh
MERGE_APPEARANCE_COSINE = 0.7  # merge_visual_sim_thresh
MAINTENANCE_EVERY_FRAMES = 10  # merge_interval = filter_interval = 5 processed frames (batches)


def contained_share(inner: Track, outer: Track) -> float:
    """Share of `inner`'s box volume inside `outer`'s (axis-aligned, as the core stores boxes)."""
    inner_low = np.subtract(inner.center, np.divide(inner.extent, 2))
    inner_high = np.add(inner.center, np.divide(inner.extent, 2))
    outer_low = np.subtract(outer.center, np.divide(outer.extent, 2))
    outer_high = np.add(outer.center, np.divide(outer.extent, 2))
    overlap = np.clip(
        np.minimum(inner_high, outer_high) - np.maximum(inner_low, outer_low), 0, None
    )
    volume = float(np.prod(inner.extent))
    return float(np.prod(overlap)) / volume if volume > 0 else 0.0


def _appearance_cosine(first: Track, second: Track) -> float:
    """Cosine of the two tracks' mean appearance (1.0 when either has none, as the core gates)."""
    a, b = first.embedding(), second.embedding()
    return 1.0 if a is None or b is None else float(a @ b)


class ConceptGraphsHooks:
    """One run's detection counts, merges and pruning."""

    def __init__(self) -> None:
        self.detections: Counter[str] = Counter()
        self.last_detected: dict[str, int] = {}
        self.last_maintenance = 0

    def after_batch(
        self, state: SceneState, events: Sequence[Event], last_frame: int
    ) -> list[Event]:
        """Count the batch's detections; every 10 frames, merge overlapping nodes and prune.

        ConceptGraphs' own filter drops every object under obj_min_detections whenever it runs;
        run every 5 processed frames that would drop objects still being seen for the first
        times, so we drop only those not detected during the whole last period (our reading).
        """
        for event in events:
            if isinstance(event, ObjectAdded | ObjectObserved):
                self.detections[event.track_id] += len(event.observations)
                self.last_detected[event.track_id] = last_frame
        if last_frame - self.last_maintenance < MAINTENANCE_EVERY_FRAMES:
            return []
        previous, self.last_maintenance = self.last_maintenance, last_frame
        live = [
            track
            for _, track in sorted(state.tracks.items())
            if track.kind == "object" and track.lifecycle != "removed"
        ]
        removed = self._merged_away(live)
        # Pruning (filter_objects): a node under the detection count that was not detected
        # during the whole last period; one still being detected keeps accumulating.
        removed |= {
            track.track_id
            for track in live
            if self.detections[track.track_id] < MIN_DETECTIONS
            and self.last_detected.get(track.track_id, last_frame) <= previous
        }
        return [
            TrackRemoved(
                track_id=track.track_id, state="removed", p_exist=track.p_exist, frame_id=None
            )
            for track in live
            if track.track_id in removed
        ]

    def _merged_away(self, live: Sequence[Track]) -> set[str]:
        """Tracks merged into another: pairs taken in descending overlap, as ConceptGraphs does."""
        pairs = []
        for inner in live:
            for outer in live:
                if inner is outer or inner.label != outer.label:
                    continue
                share = contained_share(inner, outer)
                if (
                    share > MERGE_OVERLAP
                    and _appearance_cosine(inner, outer) > MERGE_APPEARANCE_COSINE
                ):
                    pairs.append((-share, inner.track_id, outer.track_id))
        merged: set[str] = set()
        for _, inner_id, outer_id in sorted(pairs):
            if inner_id in merged or outer_id in merged:
                continue
            # The node with fewer detections is absorbed (ties: the younger identity), and its
            # detections count for the one kept (merge_obj2_into_obj1 adds num_detections).
            keep, drop = sorted(
                (inner_id, outer_id), key=lambda track_id: (-self.detections[track_id], track_id)
            )
            self.detections[keep] += self.detections[drop]
            merged.add(drop)
        return merged

    def publishable(self, track: Track) -> bool:
        """obj_min_detections: a node detected fewer than 3 times is not in the map."""
        return self.detections[track.track_id] >= MIN_DETECTIONS
