"""The columns of a scene's tracks in play, which association, the visibility gate and the
lifecycle rules read as arrays (`SceneState.arrays`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np
import numpy.typing as npt

from core.values import LifecycleState, Vec3, VerificationStatus


class TrackRow(Protocol):
    """What a track's row of columns is made from (`core.state.Track` has it)."""

    @property
    def track_id(self) -> str: ...
    @property
    def kind(self) -> str: ...
    @property
    def lifecycle(self) -> LifecycleState: ...
    @property
    def center(self) -> Vec3: ...
    @property
    def extent(self) -> Vec3: ...
    @property
    def box(self) -> tuple[float, ...] | None: ...
    @property
    def published_center(self) -> Vec3 | None: ...
    @property
    def verification(self) -> VerificationStatus | None: ...
    @property
    def visible_misses(self) -> int: ...
    @property
    def last_observed(self) -> float | None: ...
    @property
    def capture_id(self) -> str | None: ...


@dataclass(frozen=True)
class TrackArrays:
    """Columns of the tracks still in play (all but retired ones), in id order.

    Association, the visibility gate and the lifecycle rules work on these, so that their cost
    is the scene's live memory, not its history. `fold` derives a state's columns from the
    previous state's by updating the rows its events touched (`evolved`), instead of rebuilding
    them from every track.
    """

    track_ids: tuple[str, ...]
    kinds: tuple[str, ...]
    centers: npt.NDArray[np.float64]  # (n, 3): the latest center (association)
    extents: npt.NDArray[np.float64]  # (n, 3)
    box_centers: npt.NDArray[np.float64]  # (n, 3): the box the visibility gate samples
    box_extents: npt.NDArray[np.float64]  # (n, 3)
    published: npt.NDArray[np.bool_]  # ever published (it has a published center)
    gone: npt.NDArray[np.bool_]  # removed, or retired from dispute by a rejection
    missing: npt.NDArray[np.bool_]  # removed or demoted: its absence is established
    visible_misses: npt.NDArray[np.int64]  # visibility-admissible misses since last seen
    unpublished_tentative: npt.NDArray[np.bool_]  # a hypothesis never published
    last_observed: npt.NDArray[np.float64]  # tau_i (NaN when never)
    captured: npt.NDArray[np.bool_]  # a fine node the capture ledger holds (until removed)

    @classmethod
    def of(cls, tracks: Sequence[TrackRow]) -> TrackArrays:
        """The columns of these tracks (in the order given)."""
        rows = [_row(t) for t in tracks]
        count = len(rows)
        numbers = np.array([r[2] for r in rows], dtype=np.float64).reshape(count, 19)
        return cls(
            track_ids=tuple(r[0] for r in rows),
            kinds=tuple(r[1] for r in rows),
            centers=numbers[:, 0:3].copy(),
            extents=numbers[:, 3:6].copy(),
            box_centers=numbers[:, 12:15].copy(),
            box_extents=numbers[:, 15:18].copy(),
            published=numbers[:, 6] > 0,
            gone=numbers[:, 7] > 0,
            missing=numbers[:, 8] > 0,
            visible_misses=numbers[:, 9].astype(np.int64),
            unpublished_tentative=numbers[:, 10] > 0,
            last_observed=numbers[:, 11].copy(),
            captured=numbers[:, 18] > 0,
        )

    @cached_property
    def position(self) -> Mapping[str, int]:
        """Each track's row (read only: columns whose ids are the same share it)."""
        return {track_id: row for row, track_id in enumerate(self.track_ids)}

    @cached_property
    def objects(self) -> npt.NDArray[np.bool_]:
        """Which rows are objects, not fixtures (read only: shared like `position`)."""
        objects = np.array([kind == "object" for kind in self.kinds], dtype=np.bool_)
        objects.flags.writeable = False
        return objects

    def evolved(self, tracks: Mapping[str, TrackRow], touched: set[str]) -> TrackArrays:
        """The columns after the touched tracks changed (retired ones leave, new ones join)."""
        if not touched:
            return self
        position = self.position
        changed = [t for t in (tracks[i] for i in touched) if t.lifecycle != "retired"]
        if len(changed) == len(touched) and all(t.track_id in position for t in changed):
            fresh = TrackArrays.of(changed)  # only rows updated in place: the common batch
            rows = np.array([position[t.track_id] for t in changed], dtype=np.intp)
            columns = {}
            for name in _NUMERIC_COLUMNS:
                column = getattr(self, name).copy()
                column[rows] = getattr(fresh, name)
                columns[name] = column
            updated = TrackArrays(self.track_ids, self.kinds, **columns)
            # The same ids and kinds in the same rows.
            updated.__dict__["position"] = position
            if "objects" in self.__dict__:
                updated.__dict__["objects"] = self.objects
            return updated
        keep = [i for i in self.track_ids if i not in touched]
        kept = np.array([position[i] for i in keep], dtype=np.intp)
        fresh = TrackArrays.of(changed)
        order = sorted(range(len(keep) + len(changed)), key=([*keep, *fresh.track_ids]).__getitem__)
        columns = {
            name: np.concatenate((getattr(self, name)[kept], getattr(fresh, name)))[order]
            for name in _NUMERIC_COLUMNS
        }
        ids = [*keep, *fresh.track_ids]
        kinds = [*(self.kinds[position[i]] for i in keep), *fresh.kinds]
        return TrackArrays(tuple(ids[i] for i in order), tuple(kinds[i] for i in order), **columns)


_NUMERIC_COLUMNS = (
    "centers",
    "extents",
    "box_centers",
    "box_extents",
    "published",
    "gone",
    "missing",
    "visible_misses",
    "unpublished_tentative",
    "last_observed",
    "captured",
)


def _row(t: TrackRow) -> tuple[str, str, tuple[float, ...]]:
    published = t.published_center is not None
    box_center: tuple[float, ...] = t.center
    box_extent: tuple[float, ...] = t.extent
    if t.box is not None:
        box_center = tuple((t.box[i] + t.box[i + 3]) / 2 for i in range(3))
        box_extent = tuple(t.box[i + 3] - t.box[i] for i in range(3))
    return (
        t.track_id,
        t.kind,
        (
            *t.center,
            *t.extent,
            published,
            t.lifecycle == "removed" or t.verification == "rejected",
            t.lifecycle in ("removed", "demoted"),
            t.visible_misses,
            t.lifecycle == "tentative" and not published,
            np.nan if t.last_observed is None else t.last_observed,
            *box_center,
            *box_extent,
            t.capture_id is not None and t.lifecycle in ("confirmed", "demoted"),
        ),
    )
