"""What one batch says about each track: matched proposals, fixture clusters, best visibility."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from core.association import CandidatePool
from core.events import Event
from core.fixtures import FixtureProposal, ema_center
from core.geometry import Proposal
from core.observation import Frame
from core.params import Params
from core.rules import PAPER_RULES, UpdateRules
from core.state import SceneState, TrackKind
from core.support import SupportSurface, support_of
from core.transitions import (
    added_fixture,
    added_object,
    observed_fixture,
    observed_object,
    visible_miss,
)
from core.visibility import is_visible, samples_passed

FloatArray = npt.NDArray[np.float64]


@dataclass
class BatchEvidence:
    """Collects a batch's evidence frame by frame, then turns it into events once per track."""

    state: SceneState
    params: Params
    rules: UpdateRules = PAPER_RULES
    observations: dict[str, list[Proposal]] = field(default_factory=dict)
    fixtures: dict[str, FixtureProposal] = field(default_factory=dict)
    new_track_ids: list[str] = field(default_factory=list)
    visibility: dict[str, tuple[int, str]] = field(default_factory=dict)  # best (samples, frame)
    last_frame: str = ""
    last_timestamp: float = 0.0

    def __post_init__(self) -> None:
        arrays = self.state.arrays
        tracks = self.state.tracks
        self._ids = list(arrays.track_ids)
        self._kinds = [tracks[i].kind for i in self._ids]
        self._labels = [tracks[i].label for i in self._ids]
        self._centers = arrays.centers.copy()
        self._row = {track_id: row for row, track_id in enumerate(self._ids)}
        self._embeddings: dict[int, FloatArray | None] = {}
        # Removed and retired tracks get no negative evidence.
        self._live_rows = np.array(
            [
                tracks[i].lifecycle != "removed" and tracks[i].verification != "rejected"
                for i in self._ids
            ],
            dtype=bool,
        )
        self._surfaces: list[SupportSurface] | None = None
        self._eligible: npt.NDArray[np.bool_] | None = None
        self._published = np.array(
            [tracks[i].published_center is not None for i in self._ids], dtype=np.bool_
        )

    # -- association pool ---------------------------------------------------------------------

    def pool(self) -> CandidatePool:
        """Every track so far, with this batch's latest centers."""
        eligible = None
        if self._eligible is not None:  # tracks created in this batch are always eligible
            extra = len(self._ids) - len(self._eligible)
            eligible = np.concatenate((self._eligible, np.ones(extra, dtype=np.bool_)))
        recoverable = np.zeros(len(self._ids), dtype=np.bool_)
        recoverable[: len(self._published)] = self._published
        return CandidatePool(
            self._ids,
            self._kinds,
            self._labels,
            self._centers,
            self._embedding_of,
            eligible,
            recoverable,
        )

    def forget_beyond(self, timestamp: float) -> None:
        """Without persistent identity: removed and long-unseen tracks cannot be matched."""
        memory = self.rules.identity_memory_s
        if memory is None:
            return
        horizon = timestamp - memory
        eligible = []
        for track_id in self.state.arrays.track_ids:
            track = self.state.tracks[track_id]
            seen = track.last_observed
            eligible.append(track.lifecycle != "removed" and seen is not None and seen >= horizon)
        self._eligible = np.array(eligible, dtype=np.bool_)

    def _embedding_of(self, row: int) -> FloatArray | None:
        if row not in self._embeddings:
            track = self.state.tracks.get(self._ids[row])
            if track is not None:
                self._embeddings[row] = track.embedding()
            else:
                first = (
                    self.observations[self._ids[row]][0]
                    if self._ids[row] in self.observations
                    else None
                )
                self._embeddings[row] = None if first is None else first.embedding
        return self._embeddings[row]

    def _new_id(self, kind: TrackKind, label: str, center: FloatArray) -> str:
        track_id = f"trk-{self.state.next_track_number + len(self.new_track_ids):06d}"
        self.new_track_ids.append(track_id)
        self._row[track_id] = len(self._ids)
        self._ids.append(track_id)
        self._kinds.append(kind)
        self._labels.append(label)
        self._centers = np.vstack((self._centers, center[None, :]))
        return track_id

    # -- evidence -----------------------------------------------------------------------------

    def new_track(self, proposal: Proposal) -> str:
        """Identity for an object proposal no track explains: a new hypothesis."""
        return self._new_id(proposal.kind, proposal.label, proposal.center)

    def observe(self, track_id: str, proposal: Proposal) -> None:
        """A proposal matched (or created) this track; later frames gate on its latest center."""
        self.observations.setdefault(track_id, []).append(proposal)
        self._centers[self._row[track_id]] = proposal.center

    def observe_fixture(self, track_id: str | None, proposal: FixtureProposal) -> None:
        """A fixture cluster this batch supported: for its track, or a new hypothesis."""
        if track_id is None:
            track_id = self._new_id("fixture", proposal.label, proposal.center)
        self.fixtures[track_id] = proposal

    def record_visibility(self, frame: Frame) -> None:
        """Keep, per live track, the frame where most box samples passed the gate."""
        self.last_frame, self.last_timestamp = frame.frame_id, frame.timestamp
        arrays = self.state.arrays
        if not arrays.track_ids:
            return
        passed = samples_passed(
            arrays.centers,
            arrays.extents,
            frame,
            self.params.visibility,
            self.rules.visibility_gate,
        )
        for row in np.flatnonzero((passed > 0) & self._live_rows):
            track_id = arrays.track_ids[row]
            best = self.visibility.get(track_id)
            if best is None or passed[row] > best[0]:
                self.visibility[track_id] = (int(passed[row]), frame.frame_id)

    def surfaces(self) -> list[SupportSurface]:
        """Fixture tops objects may rest on, with this batch's fixture geometry."""
        if self._surfaces is None:
            surfaces = []
            for track_id in sorted(set(self.state.tracks) | set(self.fixtures)):
                track = self.state.tracks.get(track_id)
                proposal = self.fixtures.get(track_id)
                if track is not None and (
                    track.kind != "fixture" or track.verification == "rejected"
                ):
                    continue
                if track is not None and track.lifecycle == "removed" and proposal is None:
                    continue
                if proposal is not None:
                    center = (
                        ema_center(
                            track.center, proposal.center, self.params.fusion.fixture_center_alpha
                        )
                        if track is not None and track.lifecycle != "removed"
                        else (
                            float(proposal.center[0]),
                            float(proposal.center[1]),
                            float(proposal.center[2]),
                        )
                    )
                    extent = (
                        float(proposal.extent[0]),
                        float(proposal.extent[1]),
                        float(proposal.extent[2]),
                    )
                else:
                    assert track is not None
                    center, extent = track.center, track.extent
                surfaces.append(SupportSurface(track_id, center, extent))
            self._surfaces = surfaces
        return self._surfaces

    # -- events -------------------------------------------------------------------------------

    def events(self) -> list[Event]:
        """Existence updates and lifecycle transitions: new tracks first, then by track id."""
        emitted: list[Event] = []
        params = self.params
        for track_id in self.new_track_ids:
            if track_id in self.fixtures:
                emitted += added_fixture(
                    track_id, self.fixtures[track_id], self.last_frame, self.last_timestamp, params
                )
            else:
                proposals = self.observations[track_id]
                emitted += added_object(track_id, proposals, self._parents(proposals), params)
        for track_id in sorted(self.state.tracks):
            track = self.state.tracks[track_id]
            if track_id in self.fixtures:
                emitted += observed_fixture(
                    track, self.fixtures[track_id], self.last_frame, self.last_timestamp, params
                )
            elif track_id in self.observations:
                proposals = self.observations[track_id]
                emitted += observed_object(track, proposals, self._parents(proposals), params)
            elif track_id in self.visibility and is_visible(
                self.visibility[track_id][0], params.visibility
            ):
                emitted += visible_miss(
                    track, *self.visibility[track_id], params, self.rules.removal
                )
        return emitted

    def _parents(self, proposals: list[Proposal]) -> list[str | None]:
        surfaces = self.surfaces()
        return [support_of(p.center, p.bottom_z, surfaces, self.params.fixtures) for p in proposals]
