"""The tracks a batch's proposals may match, as the front end sees them while it runs (section
3.3, "Type-specific association"): the state's live columns, then the hypotheses the batch
creates, with their latest centers; class beliefs and appearance fetched lazily, once per track.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from core.association import CandidatePool
from core.belief import class_distribution
from core.geometry import Proposal
from core.state import SceneState

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


class TrackColumns:
    """The tracks proposals may match: the state's live columns, then the hypotheses created
    while the front end runs, with their latest centers. Class beliefs and appearance are
    fetched lazily, once per track."""

    def __init__(self, state: SceneState, first_number: int, from_scores: bool = True) -> None:
        arrays = state.arrays
        self.state = state
        self.count = len(arrays.track_ids)  # rows of the state; later rows are new
        self.ids = list(arrays.track_ids)
        self.kinds = list(arrays.kinds)
        self.centers = arrays.centers.copy()
        self.row = dict(arrays.position)  # its own: new hypotheses join it
        self.first_number = first_number
        self.from_scores = from_scores  # fusion.class_evidence_from_scores of the batch's params
        self.new_ids: list[str] = []
        self.observations: dict[str, list[Proposal]] = {}
        self._embeddings: dict[int, FloatArray | None] = {}
        self._beliefs: dict[int, Mapping[str, float]] = {}

    def pool(
        self, eligible: BoolArray | None, recoverable: BoolArray, rivals: BoolArray | None
    ) -> CandidatePool:
        """Every track in play; `eligible`, `recoverable` and `rivals` are over the state's rows
        (the hypotheses created here are none of the last two)."""
        extra = len(self.ids) - self.count
        if eligible is not None:
            eligible = np.concatenate((eligible, np.ones(extra, dtype=np.bool_)))
        recoverable = np.concatenate((recoverable, np.zeros(extra, dtype=np.bool_)))
        if rivals is not None:
            rivals = np.concatenate((rivals, np.zeros(extra, dtype=np.bool_)))
        return CandidatePool(
            self.ids,
            self.kinds,
            self.class_belief_of,
            self.centers,
            self.embedding_of,
            eligible,
            recoverable,
            rivals,
        )

    def embedding_of(self, row: int) -> FloatArray | None:
        """A track's appearance; one created here: its first proposal's."""
        if row not in self._embeddings:
            track = self.state.tracks.get(self.ids[row])
            if track is not None:
                self._embeddings[row] = track.embedding()
            else:
                self._embeddings[row] = self.observations[self.ids[row]][0].embedding
        return self._embeddings[row]

    def class_belief_of(self, row: int) -> Mapping[str, float]:
        """A track's p_cls; one created here: its first proposal's class evidence."""
        if row not in self._beliefs:
            track = self.state.tracks.get(self.ids[row])
            if track is not None:
                self._beliefs[row] = track.class_probabilities()
            else:
                first = self.observations[self.ids[row]][0]
                self._beliefs[row] = class_distribution(
                    first.label, first.class_scores, self.from_scores
                )
        return self._beliefs[row]

    def extent_of(self, track_id: str) -> FloatArray:
        """A track's size: its latest observed extent, the object's own (not the union box the
        visibility gate samples, which bleeding masks grow and which would take in a
        neighbour); one created here: its first proposal's extent."""
        row = self.row[track_id]
        if row < self.count:
            extent: FloatArray = self.state.arrays.extents[row]
            return extent
        return self.observations[track_id][0].extent

    def held_by_capture(self, track_id: str) -> bool:
        """A fine node attached through the capture ledger (section 3.3)."""
        row = self.row[track_id]
        return row < self.count and bool(self.state.arrays.captured[row])

    def new_track(self, proposal: Proposal) -> str:
        """Identity for a proposal no track explains: a new hypothesis."""
        track_id = f"trk-{self.first_number + len(self.new_ids):06d}"
        self.new_ids.append(track_id)
        self.row[track_id] = len(self.ids)
        self.ids.append(track_id)
        self.kinds.append(proposal.kind)
        self.centers = np.vstack((self.centers, proposal.center[None, :]))
        return track_id

    def observe(self, track_id: str, proposal: Proposal) -> None:
        """A proposal matched (or created) this track; later frames gate on its latest center."""
        self.observations.setdefault(track_id, []).append(proposal)
        self.centers[self.row[track_id]] = proposal.center
