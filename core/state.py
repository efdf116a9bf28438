"""The belief b_i of each track (equation (2)) and the scene state the log folds into."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Annotated, Any, TypedDict, Unpack

import numpy as np
import numpy.typing as npt
from pydantic import Field

from core.fixture_map import VoxelMap
from core.occupancy import OccupancyGrid
from core.params import Params
from core.plan_ledger import PlanLedger
from core.track_arrays import TrackArrays
from core.values import InspectionStatus, LifecycleState, TrackKind, Vec3, VerificationStatus

# 4: the occupancy map, the scene clock and the inspection plan; 5: fine nodes of captures;
# 6: the params hold the extensions' switches (core/profiles.py), so a state written before
# them is encoded differently (a snapshot of it is replayed instead, a rebuild rewrites it)
SNAPSHOT_FORMAT_VERSION = 7


def _none(value: object) -> bool:
    return value is None


def logistic(logodds: float) -> float:
    """p from log-odds."""
    return 1.0 / (1.0 + math.exp(-logodds))


@dataclass(frozen=True)
class Track:
    """One persistent track: class, existence, geometry, parent, appearance, identity, lifecycle."""

    track_id: str  # the persistent identity h_i
    kind: TrackKind
    lifecycle: LifecycleState  # s_i^life
    class_evidence: Mapping[str, float]  # accumulated class evidence, normalized into p_cls
    existence_logodds: float  # l_i of equation (3)
    center: Vec3  # mu_i: the latest accepted center for dynamic objects
    extent: Vec3  # stored world-frame box size used by the visibility gate
    recent_centers: tuple[Vec3, ...]  # at most 32, for Sigma_i
    parent_evidence: Mapping[str, float] = field(default_factory=dict)
    parent: str | None = None
    embedding_sum: tuple[float, ...] | None = None  # appearance a_i = sum / ||sum||
    embedding_count: int = 0
    last_observed: float | None = None  # tau_i: last reliable observation time
    last_observed_frame: str | None = None
    batches_observed: int = 0  # distinct positive batches since (re)acquisition
    visible_misses: int = 0  # visibility-admissible misses since the last positive batch
    published_center: Vec3 | None = None  # where the graph last said the track is
    pinned: bool = False  # a fixture of a frozen baseline: exempt from dynamic removal
    verification: VerificationStatus | None = None  # coarse-stage verification
    verdict_frame: str | None = None  # the observation the last verdict was about
    margin_sum: float = 0.0  # fixtures: summed top-vs-second class margin of supporting batches
    best_frame: str | None = None  # fixtures: the frame that contributed most evidence (to crop)
    best_frame_support: int = 0
    inspection_status: InspectionStatus | None = None  # fixtures: close-range inspection
    inspection_attempts: int = 0  # failed captures so far
    # Objects: the box the visibility gate samples, (low x, y, z, high x, y, z): the union of
    # the boxes observed since the object last moved. One observation's box is too small when
    # its mask was cut by the image border or by something in front; the union is the object.
    box: Annotated[tuple[float, ...] | None, Field(exclude_if=_none)] = None
    # Objects: the inspection capture that last attached it to its fixture. Such a fine node is
    # held by the capture ledger and does not re-enter the frame-level front end (section 3.3):
    # keyframes neither update it nor count misses against it; a later capture of its fixture
    # does both. Removal releases it to the front end.
    capture_id: Annotated[str | None, Field(exclude_if=_none)] = None
    # Objects: when the track was first observed (its `add`). A track first seen after another
    # was last seen may be that object seen elsewhere; one seen while the other still was is not.
    first_observed: Annotated[float | None, Field(exclude_if=_none)] = None

    def evolved(self, **changes: Unpack[TrackChanges]) -> Track:
        """A copy with `changes` (what dataclasses.replace does, without its per-field cost).

        Cached derived values (the label) are dropped so they are recomputed from the new fields.
        """
        unknown = changes.keys() - _CHANGEABLE
        if unknown:
            raise TypeError(f"Track has no changeable field {sorted(unknown)}")
        copy = object.__new__(Track)
        state = copy.__dict__
        state.update(self.__dict__)
        for name in _CACHED:
            state.pop(name, None)
        state.update(changes)
        if "_packed" in state and state.keys() >= _PACKED_FIELDS:
            del state["_packed"]  # both fields read or replaced: the block is not needed
        return copy

    @cached_property
    def label(self) -> str:
        """Most supported class; ties broken by name so the choice is deterministic."""
        return min(self.class_evidence.items(), key=lambda item: (-item[1], item[0]))[0]

    @property
    def p_exist(self) -> float:
        """p_i^exist."""
        return logistic(self.existence_logodds)

    def class_probabilities(self) -> dict[str, float]:
        """p_i^cls: class evidence normalized."""
        total = sum(self.class_evidence.values())
        return {label: weight / total for label, weight in sorted(self.class_evidence.items())}

    def parent_probabilities(self) -> dict[str, float]:
        """p_i^parent: parent evidence normalized (empty while no support is known)."""
        total = sum(self.parent_evidence.values())
        if total <= 0:
            return {}
        return {parent: weight / total for parent, weight in sorted(self.parent_evidence.items())}

    def embedding(self) -> npt.NDArray[np.float64] | None:
        """Appearance averaged by observation count, then l2-normalized (read-only: computed
        once per track value, as a batch's stages ask for it many times)."""
        return self._unit_embedding

    @cached_property
    def _unit_embedding(self) -> npt.NDArray[np.float64] | None:
        if self.embedding_sum is None:
            return None
        vector = np.asarray(self.embedding_sum, dtype=np.float64)
        norm = float(np.linalg.norm(vector))
        if norm <= 0:
            return None
        unit = vector / norm
        unit.flags.writeable = False
        return unit

    def covariance(self) -> list[list[float]]:
        """Sigma_i over the recent centers (zero until two centers exist)."""
        if len(self.recent_centers) < 2:
            return [[0.0] * 3 for _ in range(3)]
        matrix = np.cov(np.asarray(self.recent_centers, dtype=np.float64).T)
        return [[float(v) for v in row] for row in matrix]

    def to_dict(self) -> dict[str, Any]:
        """Canonical JSON-able form (snapshots, equality in tests)."""
        return {
            "track_id": self.track_id,
            "kind": self.kind,
            "lifecycle": self.lifecycle,
            "class_evidence": dict(sorted(self.class_evidence.items())),
            "existence_logodds": self.existence_logodds,
            "center": list(self.center),
            "extent": list(self.extent),
            "recent_centers": [list(c) for c in self.recent_centers],
            "parent_evidence": dict(sorted(self.parent_evidence.items())),
            "parent": self.parent,
            "embedding_sum": None if self.embedding_sum is None else list(self.embedding_sum),
            "embedding_count": self.embedding_count,
            "last_observed": self.last_observed,
            "last_observed_frame": self.last_observed_frame,
            "batches_observed": self.batches_observed,
            "visible_misses": self.visible_misses,
            "published_center": None
            if self.published_center is None
            else list(self.published_center),
            "pinned": self.pinned,
            "verification": self.verification,
            "verdict_frame": self.verdict_frame,
            "margin_sum": self.margin_sum,
            "best_frame": self.best_frame,
            "best_frame_support": self.best_frame_support,
            "inspection_status": self.inspection_status,
            "inspection_attempts": self.inspection_attempts,
            "box": None if self.box is None else list(self.box),
            **({} if self.capture_id is None else {"capture_id": self.capture_id}),
            **({} if self.first_observed is None else {"first_observed": self.first_observed}),
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> Track:
        """Inverse of `to_dict`, built like `evolved` (snapshots load hundreds of tracks per as_of).

        JSON numbers written by `to_dict` load back as floats: no per-element coercion.
        """
        embedding_sum = record["embedding_sum"]
        published = record["published_center"]
        values = dict(record)
        values.update(
            class_evidence=dict(record["class_evidence"]),
            existence_logodds=float(record["existence_logodds"]),
            center=tuple(record["center"]),
            extent=tuple(record["extent"]),
            recent_centers=tuple(map(tuple, record["recent_centers"])),
            parent_evidence=dict(record["parent_evidence"]),
            embedding_sum=None if embedding_sum is None else tuple(embedding_sum),
            published_center=None if published is None else tuple(published),
            box=None if record["box"] is None else tuple(record["box"]),
            capture_id=record.get("capture_id"),
            first_observed=record.get("first_observed"),
        )
        if values.keys() != _TRACK_FIELDS:
            raise ValueError(f"track record fields differ: {sorted(values.keys() ^ _TRACK_FIELDS)}")
        track = object.__new__(cls)
        track.__dict__.update(values)
        return track


class TrackChanges(TypedDict, total=False):
    """What `Track.evolved` may change: every field but the identity and the kind."""

    lifecycle: LifecycleState
    class_evidence: Mapping[str, float]
    existence_logodds: float
    center: Vec3
    extent: Vec3
    recent_centers: tuple[Vec3, ...]
    parent_evidence: Mapping[str, float]
    parent: str | None
    embedding_sum: tuple[float, ...] | None
    embedding_count: int
    last_observed: float | None
    last_observed_frame: str | None
    batches_observed: int
    visible_misses: int
    published_center: Vec3 | None
    pinned: bool
    verification: VerificationStatus | None
    verdict_frame: str | None
    margin_sum: float
    best_frame: str | None
    best_frame_support: int
    inspection_status: InspectionStatus | None
    inspection_attempts: int
    box: tuple[float, ...] | None
    capture_id: str | None
    first_observed: float | None


@dataclass(frozen=True, eq=False)
class PackedFloats:
    """A track's recent centers and appearance sum as a snapshot stores them: spans of one
    float64 block, made into the tuples a track holds only when they are read. Decoding a
    500-track snapshot made 80k Python floats and 16k tuples, most of which an `as_of` never
    reads (the graph does not; a tail of events touches a few tracks)."""

    block: npt.NDArray[np.float64]
    centers: tuple[int, int]  # where the centers' coordinates start in the block, and how many
    embedding: tuple[int, int] | None  # the same for the appearance sum (None: no appearance)

    def recent_centers(self) -> tuple[Vec3, ...]:
        """The centers, three coordinates each."""
        start, count = self.centers
        coordinates = iter(self.block[start : start + count].tolist())
        return tuple(zip(coordinates, coordinates, coordinates, strict=True))

    def embedding_sum(self) -> tuple[float, ...] | None:
        """The appearance sum."""
        if self.embedding is None:
            return None
        start, count = self.embedding
        return tuple(self.block[start : start + count].tolist())


class _Packed:
    """A Track field that a track decoded from a snapshot may still hold packed (its `_packed`,
    a `PackedFloats`): made the first time it is read, then kept in the track like any field
    (as `cached_property` keeps its value). A track built any other way holds the field itself,
    which attribute lookup finds before this descriptor, so it costs such tracks nothing."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, track: Track | None, owner: type | None = None) -> Any:
        if track is None:
            return self
        packed: PackedFloats | None = track.__dict__.get("_packed")
        if packed is None:
            raise AttributeError(f"Track has no {self.name}")
        value = getattr(packed, self.name)()
        track.__dict__[self.name] = value
        return value


_PACKED_FIELDS = frozenset({"recent_centers", "embedding_sum"})
for _name in sorted(_PACKED_FIELDS):  # installed after the dataclass: its __init__ is unchanged
    setattr(Track, _name, _Packed(_name))


def packed_track(values: Iterable[tuple[str, Any]], packed: PackedFloats) -> Track:
    """A track from (name, value) of every field but the two `packed` holds (a snapshot's
    decode: no check, no copy)."""
    track = object.__new__(Track)
    state = track.__dict__
    state.update(values)
    state["_packed"] = packed
    return track


_TRACK_FIELDS = frozenset(f.name for f in fields(Track))
_CHANGEABLE = TrackChanges.__optional_keys__
_CACHED = frozenset(
    name for name, value in vars(Track).items() if isinstance(value, cached_property)
)


@dataclass(frozen=True)
class BaselineRecord:
    """A frozen baseline of this scene: version, the seq it was frozen at, its fixtures, sha256."""

    version: int
    seq: int
    sha256: str
    fixture_ids: tuple[str, ...]


@dataclass(frozen=True)
class SceneState:
    """M_t: the persistent track table, plus what the log says about the scene itself."""

    params: Params = field(default_factory=Params)
    name: str = ""
    head_seq: int = -1  # seq of the last event folded in; scene_created is seq 0
    tracks: Mapping[str, Track] = field(default_factory=dict)
    next_track_number: int = 1
    # The fixture voxel map: per voxel, how many fixture masks covered it and the summed class
    # similarities, in the order of params.fixtures.taxonomy (sorted arrays; its clusters are
    # derived from it and carried from state to state by the fold).
    voxels: VoxelMap = field(default_factory=VoxelMap)
    baselines: tuple[BaselineRecord, ...] = ()
    source_baseline: Mapping[str, Any] | None = None  # the package this session started from
    occupancy: OccupancyGrid = field(default_factory=OccupancyGrid.empty)  # A_t
    clock: float | None = None  # the newest batch's time (from its occupancy evidence)
    plan: PlanLedger = field(default_factory=PlanLedger)  # inspection lock and failures

    @cached_property
    def arrays(self) -> TrackArrays:
        """Columns of every track but retired ones, in id order."""
        return TrackArrays.of(
            [t for t in (self.tracks[i] for i in sorted(self.tracks)) if t.lifecycle != "retired"]
        )

    def with_arrays_from(self, previous: SceneState, touched: set[str]) -> SceneState:
        """This state, its columns derived from `previous`'s when those were built."""
        columns = previous.__dict__.get("arrays")
        if columns is not None:
            self.__dict__["arrays"] = columns.evolved(self.tracks, touched)
        return self

    def to_dict(self) -> dict[str, Any]:
        """Canonical JSON-able form: snapshots store it, tests compare it."""
        return {
            "format_version": SNAPSHOT_FORMAT_VERSION,
            "params": self.params.to_dict(),
            "name": self.name,
            "head_seq": self.head_seq,
            "next_track_number": self.next_track_number,
            "tracks": [self.tracks[i].to_dict() for i in sorted(self.tracks)],
            "voxels": self.voxels.records(),
            "baselines": [
                {
                    "version": b.version,
                    "seq": b.seq,
                    "sha256": b.sha256,
                    "fixture_ids": list(b.fixture_ids),
                }
                for b in self.baselines
            ],
            "source_baseline": self.source_baseline,
            "occupancy": self.occupancy.to_dict(),
            "clock": self.clock,
            "plan": self.plan.to_dict(),
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> SceneState:
        """Inverse of `to_dict`; a different format version raises ValueError."""
        if record.get("format_version") != SNAPSHOT_FORMAT_VERSION:
            raise ValueError(f"snapshot format {record.get('format_version')} is not supported")
        tracks = {t["track_id"]: Track.from_dict(t) for t in record["tracks"]}
        return cls(
            params=Params.recorded(record["params"]),
            name=record["name"],
            head_seq=int(record["head_seq"]),
            tracks=tracks,
            next_track_number=int(record["next_track_number"]),
            voxels=VoxelMap.from_records(record["voxels"]),
            baselines=tuple(
                BaselineRecord(b["version"], b["seq"], b["sha256"], tuple(b["fixture_ids"]))
                for b in record["baselines"]
            ),
            source_baseline=record["source_baseline"],
            occupancy=OccupancyGrid.from_dict(record["occupancy"]),
            clock=None if record["clock"] is None else float(record["clock"]),
            plan=PlanLedger.from_dict(record["plan"]),
        )
