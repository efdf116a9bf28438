"""decide: one semantic update batch -> typed events. Reads as section 3.3 of the paper."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from core.association import CandidatePool, associate
from core.belief import update_existence
from core.events import (
    Event,
    TrackAdded,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackUpdated,
)
from core.geometry import Proposal, ground_detection
from core.lifecycle import moved_distance, should_confirm, should_demote, should_move, should_remove
from core.observation import Batch, Frame
from core.params import Params
from core.state import SceneState, Track, Vec3, logistic
from core.visibility import is_visible, samples_passed

FloatArray = npt.NDArray[np.float64]


def decide(state: SceneState, batch: Batch, params: Params | None = None) -> list[Event]:
    """Events of one batch; pure and deterministic. `params` defaults to the scene's own."""
    params = params or state.params
    evidence = BatchEvidence(state, params)
    for frame in batch.frames:
        # 1. Grounded observations: back-project each mask's valid depth (section 3.2).
        proposals = ground_frame(frame, params)
        # 2. Dynamic association: class, 3D distance < 0.8 m, appearance > 0.78, greedy 1:1,
        #    unique-class fallback; removed tracks take part (section 3.3).
        matches = associate(proposals, evidence.pool(), params.association)
        for j, proposal in enumerate(proposals):
            evidence.observe(matches.get(j) or evidence.new_track(proposal), proposal)
        # 3. Visibility gate for the tracks not matched so far: samples of the stored box.
        evidence.record_visibility(frame)
    # 4. One existence update per track per batch (equation (3)), then lifecycle events.
    return evidence.events()


def ground_frame(frame: Frame, params: Params) -> list[Proposal]:
    """Object proposals of one frame; masks with too little valid depth are rejected."""
    proposals = []
    for detection in frame.detections:
        if detection.kind != "object":
            continue  # fixtures have their own front end
        proposal = ground_detection(
            detection,
            frame,
            params.proposal,
            params.visibility.min_range_m,
            params.visibility.max_range_m,
        )
        if proposal is not None:
            proposals.append(proposal)
    return proposals


@dataclass
class _NewTrack:
    track_id: str
    kind: str
    label: str


@dataclass
class BatchEvidence:
    """What one batch says about each track: its matched proposals, or its best visibility."""

    state: SceneState
    params: Params
    observations: dict[str, list[Proposal]] = field(default_factory=dict)
    new_tracks: list[_NewTrack] = field(default_factory=list)
    visibility: dict[str, tuple[int, str]] = field(default_factory=dict)  # best (samples, frame)

    def __post_init__(self) -> None:
        arrays = self.state.arrays
        self._ids = list(arrays.track_ids)
        self._kinds = [self.state.tracks[i].kind for i in self._ids]
        self._labels = [self.state.tracks[i].label for i in self._ids]
        self._centers = arrays.centers.copy()
        self._row = {track_id: row for row, track_id in enumerate(self._ids)}
        self._embeddings: dict[int, FloatArray | None] = {}
        self._live_rows = np.array(
            [self.state.tracks[i].lifecycle != "removed" for i in self._ids], dtype=bool
        )

    def pool(self) -> CandidatePool:
        """Every track so far, with this batch's latest centers."""
        return CandidatePool(
            self._ids, self._kinds, self._labels, self._centers, self._embedding_of
        )

    def _embedding_of(self, row: int) -> FloatArray | None:
        if row not in self._embeddings:
            track = self.state.tracks.get(self._ids[row])
            if track is not None:
                self._embeddings[row] = track.embedding()
            else:
                first = self.observations[self._ids[row]][0]
                self._embeddings[row] = first.embedding
        return self._embeddings[row]

    def new_track(self, proposal: Proposal) -> str:
        """Identity for a proposal no track explains: a new hypothesis."""
        number = self.state.next_track_number + len(self.new_tracks)
        track_id = f"trk-{number:06d}"
        self.new_tracks.append(_NewTrack(track_id, proposal.kind, proposal.label))
        self._row[track_id] = len(self._ids)
        self._ids.append(track_id)
        self._kinds.append(proposal.kind)
        self._labels.append(proposal.label)
        self._centers = np.vstack((self._centers, proposal.center[None, :]))
        return track_id

    def observe(self, track_id: str, proposal: Proposal) -> None:
        """A proposal matched (or created) this track; later frames gate on its latest center."""
        self.observations.setdefault(track_id, []).append(proposal)
        self._centers[self._row[track_id]] = proposal.center

    def record_visibility(self, frame: Frame) -> None:
        """Keep, per live unmatched track, the frame where most box samples passed the gate."""
        arrays = self.state.arrays
        if not arrays.track_ids:
            return
        passed = samples_passed(arrays.centers, arrays.extents, frame, self.params.visibility)
        for row in np.flatnonzero((passed > 0) & self._live_rows):
            track_id = arrays.track_ids[row]
            best = self.visibility.get(track_id)
            if best is None or passed[row] > best[0]:
                self.visibility[track_id] = (int(passed[row]), frame.frame_id)

    def events(self) -> list[Event]:
        """Existence updates and lifecycle transitions, in track order."""
        emitted: list[Event] = []
        for new in self.new_tracks:
            emitted.append(self._added(new))
        for track_id in sorted(self.state.tracks):
            track = self.state.tracks[track_id]
            if track_id in self.observations:
                emitted.extend(self._observed(track))
            elif track_id in self.visibility and is_visible(
                self.visibility[track_id][0], self.params.visibility
            ):
                emitted.extend(self._visible_miss(track))
        return emitted

    def _observation_details(
        self, track: Track | None, proposals: list[Proposal]
    ) -> dict[str, Any]:
        """The batch's observations of one track, as evolve needs them."""
        dim = None
        if track is not None and track.embedding_sum is not None:
            dim = len(track.embedding_sum)
        embeddings = [p.embedding for p in proposals if p.embedding is not None]
        if dim is None and embeddings:
            dim = embeddings[0].shape[0]
        embeddings = [e for e in embeddings if e.shape[0] == dim]
        embedding_sum = [float(v) for v in np.sum(embeddings, axis=0)] if embeddings else None
        return {
            "evidence": "observed",
            "observations": [
                {
                    "frame_id": p.frame_id,
                    "label": p.label,
                    "score": float(p.score),
                    "center": [float(v) for v in p.center],
                    "extent": [float(v) for v in p.extent],
                    "valid_pixels": p.valid_pixels,
                    "parent": None,
                }
                for p in proposals
            ],
            "embedding_sum": embedding_sum,
            "embedding_count": len(embeddings),
            "timestamp": float(proposals[-1].timestamp),
        }

    def _added(self, new: _NewTrack) -> Event:
        proposals = self.observations[new.track_id]
        logodds = update_existence(
            self.params.existence.prior_logodds, self.params.existence, observed=True
        )
        details = self._observation_details(None, proposals)
        details.update(
            kind=new.kind, existence_logodds=logodds, p_exist=logistic(logodds), batches_observed=1
        )
        return TrackAdded(new.track_id, "tentative", proposals[0].frame_id, details)

    def _observed(self, track: Track) -> list[Event]:
        proposals = self.observations[track.track_id]
        frame_id = proposals[-1].frame_id
        existence, lifecycle_params = self.params.existence, self.params.lifecycle
        # A removed track that is re-acquired keeps its identity and restarts as a hypothesis.
        reacquired = track.lifecycle == "removed"
        prior = existence.prior_logodds if reacquired else track.existence_logodds
        logodds = update_existence(prior, existence, observed=True)
        p_exist = logistic(logodds)
        batches = 1 if reacquired else track.batches_observed + 1
        lifecycle = "tentative" if reacquired else track.lifecycle
        details = self._observation_details(track, proposals)
        details.update(
            existence_logodds=logodds,
            p_exist=p_exist,
            batches_observed=batches,
            reacquired=reacquired,
        )
        emitted: list[Event] = [TrackUpdated(track.track_id, lifecycle, frame_id, details)]
        center: Vec3 = (
            float(proposals[-1].center[0]),
            float(proposals[-1].center[1]),
            float(proposals[-1].center[2]),
        )
        if should_confirm(lifecycle, p_exist, batches, lifecycle_params):
            lifecycle = "confirmed"
            emitted.append(
                TrackConfirmed(
                    track.track_id,
                    lifecycle,
                    frame_id,
                    {"p_exist": p_exist, "center": list(center), "batches_observed": batches},
                )
            )
        if lifecycle == "confirmed" and should_move(
            track.published_center, center, lifecycle_params
        ):
            assert track.published_center is not None
            emitted.append(
                TrackMoved(
                    track.track_id,
                    lifecycle,
                    frame_id,
                    {
                        "from": list(track.published_center),
                        "to": list(center),
                        "distance": moved_distance(track.published_center, center),
                    },
                )
            )
        return emitted

    def _visible_miss(self, track: Track) -> list[Event]:
        samples, frame_id = self.visibility[track.track_id]
        existence, lifecycle_params = self.params.existence, self.params.lifecycle
        logodds = update_existence(track.existence_logodds, existence, visible_miss=True)
        p_exist = logistic(logodds)
        misses = track.visible_misses + 1
        details = {
            "evidence": "visible_miss",
            "samples_passed": samples,
            "samples_total": self.params.visibility.box_samples_per_axis**3,
            "existence_logodds": logodds,
            "p_exist": p_exist,
            "visible_misses": misses,
        }
        lifecycle = track.lifecycle
        emitted: list[Event] = [TrackUpdated(track.track_id, lifecycle, frame_id, details)]
        if should_demote(lifecycle, p_exist, lifecycle_params):
            lifecycle = "demoted"
            emitted.append(TrackDemoted(track.track_id, lifecycle, frame_id, {"p_exist": p_exist}))
        if should_remove(lifecycle, p_exist, misses, False, lifecycle_params):
            lifecycle = "removed"
            emitted.append(
                TrackRemoved(
                    track.track_id,
                    lifecycle,
                    frame_id,
                    {"p_exist": p_exist, "visible_misses": misses},
                )
            )
        return emitted
