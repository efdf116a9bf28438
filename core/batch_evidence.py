"""What one batch says about each track: matched proposals, fixture clusters, best visibility.

Its work is bounded by the tracks in play near the camera, not by the scene's history: retired
hypotheses are not in the state's columns at all, the visibility gate samples only the boxes
that can be in view, and events are decided only for tracks the batch has evidence about.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from core.association import CandidatePool, appearance_agrees, mutual_matches
from core.belief import class_compatibility, class_distribution
from core.events import Event, TrackReparented, TrackRetired
from core.fixtures import FixtureProposal
from core.geometry import Proposal
from core.observation import Frame
from core.params import Params
from core.rules import PAPER_RULES, UpdateRules
from core.state import SceneState
from core.support import SupportSurface, support_of, surface_of
from core.transitions import (
    added_fixture,
    added_object,
    observed_fixture,
    observed_object,
    reidentified_object,
    retired,
    visible_miss,
)
from core.values import TrackKind
from core.visibility import Sighting, in_view_rows, observable, samples_passed

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
    visibility: dict[str, Sighting] = field(default_factory=dict)  # best view of each track
    merged: dict[str, str] = field(default_factory=dict)  # second fixture track -> its keeper
    last_frame: str = ""
    last_timestamp: float = 0.0

    def __post_init__(self) -> None:
        arrays = self.state.arrays
        self._ids = list(arrays.track_ids)
        self._kinds: list[str] = list(arrays.kinds)
        self._centers = arrays.centers.copy()
        self._row = {track_id: row for row, track_id in enumerate(self._ids)}
        self._embeddings: dict[int, FloatArray | None] = {}
        self._beliefs: dict[int, Mapping[str, float]] = {}
        # Removed and rejected tracks get no negative evidence, and neither do fine nodes held
        # by the capture ledger: only a capture of their fixture speaks of them (section 3.3).
        self._live_rows = ~arrays.gone & ~arrays.captured
        self._surfaces: list[SupportSurface] | None = None
        self._eligible: npt.NDArray[np.bool_] | None = None

    # -- association pool ---------------------------------------------------------------------

    def pool(self) -> CandidatePool:
        """Every track in play, with this batch's latest centers."""
        arrays = self.state.arrays
        extra = len(self._ids) - len(arrays.track_ids)  # tracks created in this batch
        eligible = None
        if self._eligible is not None:
            eligible = np.concatenate((self._eligible, np.ones(extra, dtype=np.bool_)))
        recoverable = np.concatenate(
            (arrays.published & self._absent(), np.zeros(extra, dtype=np.bool_))
        )
        return CandidatePool(
            self._ids,
            self._kinds,
            self._class_belief_of,
            self._centers,
            self._embedding_of,
            eligible,
            recoverable,
        )

    def _absent(self) -> npt.NDArray[np.bool_]:
        """Absence established: removed or demoted, or its place seen empty in enough batches
        (this one counting once when it showed the place and no proposal matched the track)."""
        arrays = self.state.arrays
        seen_empty = np.zeros(len(arrays.track_ids), dtype=np.int64)
        for track_id, sighting in self.visibility.items():
            if track_id not in self.observations and observable(sighting, self.params.visibility):
                seen_empty[self._row[track_id]] = 1
        misses = arrays.visible_misses + seen_empty
        absent: npt.NDArray[np.bool_] = arrays.missing | (
            misses >= self.params.association.fallback_min_misses
        )
        return absent

    def held_by_capture(self, track_id: str) -> bool:
        """A fine node attached through the capture ledger: a frame's proposal it explains is
        set aside, neither an update of it nor a new hypothesis (section 3.3)."""
        row = self._row[track_id]
        arrays = self.state.arrays
        return row < len(arrays.track_ids) and bool(arrays.captured[row])

    def forget_beyond(self, timestamp: float) -> None:
        """Without persistent identity: removed and long-unseen tracks cannot be matched."""
        memory = self.rules.identity_memory_s
        if memory is None:
            return
        arrays = self.state.arrays
        with np.errstate(invalid="ignore"):
            recent = arrays.last_observed >= timestamp - memory  # NaN (never seen): False
        self._eligible = ~arrays.gone & recent

    def _embedding_of(self, row: int) -> FloatArray | None:
        if row not in self._embeddings:
            track = self.state.tracks.get(self._ids[row])
            if track is not None:
                self._embeddings[row] = track.embedding()
            else:  # created in this batch: its first proposal's appearance
                self._embeddings[row] = self.observations[self._ids[row]][0].embedding
        return self._embeddings[row]

    def _class_belief_of(self, row: int) -> Mapping[str, float]:
        if row not in self._beliefs:
            track = self.state.tracks.get(self._ids[row])
            if track is not None:
                self._beliefs[row] = track.class_probabilities()
            else:
                first = self.observations[self._ids[row]][0]
                self._beliefs[row] = class_distribution(first.label, first.class_scores)
        return self._beliefs[row]

    def _new_id(self, kind: TrackKind, center: FloatArray) -> str:
        track_id = f"trk-{self.state.next_track_number + len(self.new_track_ids):06d}"
        self.new_track_ids.append(track_id)
        self._row[track_id] = len(self._ids)
        self._ids.append(track_id)
        self._kinds.append(kind)
        self._centers = np.vstack((self._centers, center[None, :]))
        return track_id

    # -- evidence -----------------------------------------------------------------------------

    def new_track(self, proposal: Proposal) -> str:
        """Identity for an object proposal no track explains: a new hypothesis."""
        return self._new_id(proposal.kind, proposal.center)

    def extent_of(self, track_id: str) -> FloatArray:
        """A track's size: its visibility box, the union of its views (partial views give
        partial boxes); one created in this batch: its first proposal's extent."""
        arrays = self.state.arrays
        row = self._row[track_id]
        if row < len(arrays.track_ids):
            extent: FloatArray = arrays.box_extents[row]
            return extent
        return self.observations[track_id][0].extent

    def observe(self, track_id: str, proposal: Proposal) -> None:
        """A proposal matched (or created) this track; later frames gate on its latest center."""
        self.observations.setdefault(track_id, []).append(proposal)
        self._centers[self._row[track_id]] = proposal.center

    def observe_fixture(self, track_id: str | None, proposal: FixtureProposal) -> None:
        """A fixture cluster this batch supported: for its track, or a new hypothesis."""
        if track_id is None:
            track_id = self._new_id("fixture", proposal.center)
        self.fixtures[track_id] = proposal

    def record_visibility(self, frame: Frame) -> None:
        """Keep, per live track that could be in view, its best view of this batch."""
        self.last_frame, self.last_timestamp = frame.frame_id, frame.timestamp
        arrays = self.state.arrays
        rows = in_view_rows(arrays.box_centers, arrays.box_extents, frame, self.params.visibility)
        rows = rows[self._live_rows[rows]]
        if rows.size == 0:
            return
        sightings = samples_passed(
            arrays.box_centers[rows],
            arrays.box_extents[rows],
            frame,
            self.params.visibility,
            self.rules.visibility_gate,
            self.rules.miss_evidence,
            probes=arrays.centers[rows],
        )
        for row, sighting in zip(rows, sightings, strict=True):
            if sighting.passed == 0:
                continue
            track_id = arrays.track_ids[row]
            best = self.visibility.get(track_id)
            if best is None or self._rank(sighting) > self._rank(best):
                self.visibility[track_id] = sighting.seen_in(frame.frame_id)

    def _rank(self, sighting: Sighting) -> tuple[bool, int, float]:
        """Which of a batch's sightings of a track stands for the batch: one that would count a
        miss first, then the one showing more of the box."""
        gate = observable(sighting, self.params.visibility, self.rules.visibility_gate)
        return (gate, sighting.passed, sighting.expected_fraction)

    def surfaces(self) -> list[SupportSurface]:
        """Fixture tops objects may rest on, with this batch's fixture geometry."""
        if self._surfaces is None:
            arrays = self.state.arrays
            fixture_ids = {
                i
                for i, kind in zip(arrays.track_ids, arrays.kinds, strict=True)
                if kind == "fixture"
            }
            self._surfaces = [
                surface
                for track_id in sorted((fixture_ids | set(self.fixtures)) - set(self.merged))
                if (
                    surface := surface_of(
                        self.state.tracks.get(track_id),
                        track_id,
                        self.fixtures.get(track_id),
                        self.params.fusion.fixture_center_alpha,
                    )
                )
                is not None
            ]
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
        stale = set(self._stale_hypotheses())
        concerned = set(self.fixtures) | set(self.observations) | set(self.visibility) | stale
        reidentified = self._reidentifications()
        concerned -= set(self.merged) | set(reidentified) | {h for h, _ in reidentified.values()}
        for track_id in sorted(concerned - set(self.new_track_ids)):
            track = self.state.tracks[track_id]
            if track_id in self.fixtures:
                emitted += observed_fixture(
                    track, self.fixtures[track_id], self.last_frame, self.last_timestamp, params
                )
            elif track_id in self.observations:
                proposals = self.observations[track_id]
                emitted += observed_object(track, proposals, self._parents(proposals), params)
            elif track_id in self.visibility and observable(
                self.visibility[track_id], params.visibility, self.rules.visibility_gate
            ):
                sighting = self.visibility[track_id]
                emitted += visible_miss(
                    track, sighting.passed, sighting.frame_id, params, self.rules.removal
                )
            if _removed_unpublished(emitted, track_id, track.published_center):
                emitted += retired(track, self.last_frame, "removed")
            elif track_id in stale:
                emitted += retired(
                    track, self.last_frame, "removed" if track.lifecycle == "removed" else "unseen"
                )
        for track_id, (hypothesis, cosine) in sorted(reidentified.items()):
            emitted += reidentified_object(
                self.state.tracks[track_id],
                self.state.tracks[hypothesis],
                cosine,
                self.last_frame,
                params,
            )
            emitted += retired(self.state.tracks[hypothesis], self.last_frame, "merged", track_id)
        return emitted + self._merges(emitted, set(reidentified))

    def _reidentifications(self) -> dict[str, tuple[str, float]]:
        """Missing objects that are hypotheses seen since elsewhere: object -> (hypothesis,
        appearance cosine).

        The object: published, its absence established (`_absent`), not matched in this batch.
        The hypothesis: an object track never published, not matched in this batch, last seen
        after the object was. Their classes are compatible, and each is the other's best
        appearance match past the gate, by the fallback margin over every other candidate on
        either side (a mug carried among mugs keeps its identity; a mug still in place lends
        none). The work is bounded by the live hypotheses, which retire when unseen.
        """
        params = self.params.association
        if not (params.unique_class_fallback and params.reidentify_hypotheses):
            return {}
        arrays = self.state.arrays
        count = len(arrays.track_ids)
        objects = (np.asarray(self._kinds[:count]) == "object") & ~arrays.captured
        if self._eligible is not None:
            objects &= self._eligible
        for track_id in self.observations:
            row = self._row[track_id]
            if row < count:
                objects[row] = False
        hypotheses = objects & arrays.unpublished_tentative & ~arrays.gone
        if not hypotheses.any():
            return {}
        missing = np.flatnonzero(objects & arrays.published & self._absent())
        if missing.size == 0:
            return {}
        # Only a hypothesis seen after some missing object was can be one of them.
        with np.errstate(invalid="ignore"):
            hypotheses &= arrays.last_observed > np.nanmin(arrays.last_observed[missing])
        hypotheses = np.flatnonzero(hypotheses)

        def cosine(h: int, m: int) -> float | None:
            if not arrays.last_observed[m] < arrays.last_observed[h]:
                return None  # the hypothesis was not seen after the object
            if (
                class_compatibility(self._class_belief_of(h), self._class_belief_of(m))
                < params.min_class_compatibility
            ):
                return None
            a, b = self._embedding_of(h), self._embedding_of(m)
            return None if a is None or b is None or a.shape != b.shape else float(a @ b)

        return {
            arrays.track_ids[m]: (arrays.track_ids[h], score)
            for h, m, score in mutual_matches(hypotheses.tolist(), missing.tolist(), cosine, params)
        }

    def _duplicate_objects(self) -> dict[str, str]:
        """Second tracks of one object: a live track whose center lies inside the object box
        (center and extent) of a track this batch matched, or whose box holds that track's
        center, of a compatible class and appearance, neither one missing; the younger one ->
        the older (an unpublished one -> a published one)."""
        arrays = self.state.arrays
        count = len(arrays.track_ids)
        if not self.params.association.absorb_contained_tracks or count < 2:
            return {}
        objects = self._live_rows & ~arrays.missing & (np.asarray(self._kinds[:count]) == "object")
        if self._eligible is not None:  # a track association may not match is not one either
            objects &= self._eligible
        rows = np.flatnonzero(objects)
        centers, half = arrays.centers[rows], arrays.extents[rows] / 2
        widest = half[:, 0].max(initial=0.0)
        merged: dict[str, str] = {}
        for track_id in sorted(self.observations):
            row = self._row[track_id]
            if row >= count or not objects[row] or track_id in merged:
                continue
            # x first (one axis over every candidate), then the whole test on the few left.
            mine = arrays.extents[row] / 2
            near = np.flatnonzero(
                np.abs(centers[:, 0] - arrays.centers[row, 0]) <= max(mine[0], widest)
            )
            gap = np.abs(centers[near] - arrays.centers[row])
            held = (gap <= mine).all(axis=1) | (gap <= half[near]).all(axis=1)
            for other in rows[near[held]].tolist():
                other_id = arrays.track_ids[other]
                if other == row or other_id in self.observations or other_id in merged:
                    continue
                if not self._same_object(row, other):
                    continue
                keep, drop = sorted((track_id, other_id))  # ids grow with age
                if arrays.published[self._row[drop]] and not arrays.published[self._row[keep]]:
                    keep, drop = drop, keep
                if drop in merged.values():
                    continue  # it keeps another track this batch: no chain of merges
                merged[drop] = keep
                if drop == track_id:
                    break
        return merged

    def _same_object(self, row: int, other: int) -> bool:
        params = self.params.association
        compatible = (
            class_compatibility(self._class_belief_of(row), self._class_belief_of(other))
            >= params.min_class_compatibility
        )
        return compatible and appearance_agrees(
            self._embedding_of(row), self._embedding_of(other), params.min_appearance_cosine
        )

    def _merges(self, emitted: list[Event], busy: set[str]) -> list[Event]:
        """Second tracks retire into their keepers; a fixture's objects follow, unless this
        batch already gave them a parent. Tracks re-identified in this batch (`busy`) are left
        alone."""
        events: list[Event] = []
        gone = {e.track_id for e in emitted if isinstance(e, TrackRetired)} | busy
        for track_id, keeper in sorted(self._duplicate_objects().items()):
            if track_id not in gone and keeper not in gone:
                events += retired(self.state.tracks[track_id], self.last_frame, "merged", keeper)
        reparented = {e.track_id for e in emitted if isinstance(e, TrackReparented)}
        for track_id, keeper in sorted(self.merged.items()):
            events += retired(self.state.tracks[track_id], self.last_frame, "merged", keeper)
            children = (
                t
                for t in self.state.tracks.values()
                if t.parent == track_id
                and t.kind == "object"
                and t.lifecycle != "retired"
                and t.track_id not in reparented
            )
            for child in sorted(children, key=lambda t: t.track_id):
                events.append(
                    TrackReparented(
                        track_id=child.track_id,
                        state=child.lifecycle,
                        frame_id=self.last_frame,
                        old_parent=track_id,
                        new_parent=keeper,
                    )
                )
        return events

    def _stale_hypotheses(self) -> list[str]:
        """Hypotheses never published: removed ones, and those unseen for too long (section 3.3:
        raw hypotheses are unpublished tracks; these no longer count as any)."""
        arrays = self.state.arrays
        horizon = self.last_timestamp - self.params.lifecycle.retire_unseen_hypothesis_s
        with np.errstate(invalid="ignore"):
            unseen = arrays.unpublished_tentative & ~(arrays.last_observed >= horizon)
        removed_unpublished = arrays.gone & ~arrays.published
        rows = np.flatnonzero(unseen | removed_unpublished)
        return [
            arrays.track_ids[row]
            for row in rows
            if arrays.track_ids[row] not in self.observations
            and arrays.track_ids[row] not in self.fixtures
            and self.state.tracks[arrays.track_ids[row]].verification != "pending"
        ]

    def _parents(self, proposals: list[Proposal]) -> list[str | None]:
        surfaces = self.surfaces()
        return [support_of(p.center, p.bottom_z, surfaces, self.params.fixtures) for p in proposals]


def _removed_unpublished(events: list[Event], track_id: str, published: object) -> bool:
    """A hypothesis this batch removed, never published: it retires at once."""
    return (
        published is None
        and bool(events)
        and events[-1].track_id == track_id
        and events[-1].type == "remove"
    )
