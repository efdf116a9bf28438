"""The snapshot body: a scene state as compressed bytes, deterministic for equal states."""

from __future__ import annotations

import dataclasses
import struct
from typing import Any

import numpy as np
import numpy.typing as npt
import orjson
import zstandard

from core.fixture_map import VoxelMap
from core.state import SNAPSHOT_FORMAT_VERSION, PackedFloats, SceneState, Track, packed_track

__all__ = [
    "READABLE_VERSIONS",
    "SNAPSHOT_HEADER",
    "SNAPSHOT_VERSION",
    "decode_snapshot",
    "encode_snapshot",
]

# Body codecs on top of the state's dict format (a change of that makes every old snapshot
# unreadable, so they are replayed instead). 3: float arrays as one float64 block after the
# JSON; 4: the same, the tracks stored by column instead of one object per track, and the
# fixture voxel map as arrays after the float block. Version 3 bodies are still read; `pbdag
# rebuild` rewrites them in version 4.
SNAPSHOT_VERSION = 100 * SNAPSHOT_FORMAT_VERSION + 4
SNAPSHOT_VERSION_ROWS = 100 * SNAPSHOT_FORMAT_VERSION + 3
READABLE_VERSIONS = frozenset({SNAPSHOT_VERSION, SNAPSHOT_VERSION_ROWS})
FLOAT_BLOCKS = ("recent_centers", "embedding_sum")  # most of a snapshot's numbers
SNAPSHOT_HEADER = struct.Struct("<I")  # the length of the JSON part
SNAPSHOT_ZSTD_LEVEL = 1
TRACK_FIELDS = tuple(f.name for f in dataclasses.fields(Track))
_OPTIONAL_FIELDS = ("capture_id", "first_observed")  # left out of a track's dict when None


def encode_snapshot(state: SceneState) -> bytes:
    """Compressed snapshot body (version 4); deterministic bytes for equal states.

    zstandard(u32 length, the state's JSON, float64 block). The JSON is the state's dict with
    its tracks by column: `tracks` maps each Track field to the list of its values in track
    order. Each track's long float arrays (`FLOAT_BLOCKS`) leave the JSON, which keeps their
    length, for one exact little-endian float64 block after it: every track's recent centers,
    then every track's embedding sum, in track order. Parsing decimal text of ~80k floats costs
    more than the rest of an as_of; building a track from columns costs less than from its own
    JSON object. The fixture voxel map (`voxels`) is stored last, as its arrays: the packed keys
    (int64), the counts (int64) and the class-score sums (float64, row-major), its JSON entry
    holding only its shape; a house's map of 100k voxels was most of the JSON, and of the time.
    """
    voxels = state.voxels
    record = dataclasses.replace(state, voxels=VoxelMap()).to_dict()
    record["voxels"] = {"count": len(voxels), "width": int(voxels.sums.shape[1])}
    rows = record["tracks"]
    columns: dict[str, list[Any]] = {name: [] for name in TRACK_FIELDS}
    for track in rows:
        for name in _OPTIONAL_FIELDS:
            track.setdefault(name, None)
        for name in TRACK_FIELDS:
            columns[name].append(track[name])
    floats = _float_block(columns)
    record["tracks"] = columns
    header = orjson.dumps(record)
    voxel_arrays = (
        voxels.keys.astype("<i8").tobytes()
        + voxels.counts.astype("<i8").tobytes()
        + voxels.sums.astype("<f8").tobytes()
    )
    body = SNAPSHOT_HEADER.pack(len(header)) + header + floats + voxel_arrays
    return zstandard.ZstdCompressor(level=SNAPSHOT_ZSTD_LEVEL).compress(body)


def _float_block(columns: dict[str, list[Any]]) -> bytes:
    """The float64 block of the `FLOAT_BLOCKS` columns, each value replaced by its length."""
    arrays: list[npt.NDArray[np.float64]] = []
    for key in FLOAT_BLOCKS:
        column = columns[key]
        for index, value in enumerate(column):
            if value is not None:
                values = np.asarray(value, dtype="<f8").reshape(-1)
                column[index] = len(values)
                arrays.append(values)
    return np.concatenate(arrays).tobytes() if arrays else b""


def decode_snapshot(body: bytes, version: int = SNAPSHOT_VERSION) -> SceneState:
    """Inverse of `encode_snapshot` (`version`: the body's, one of `READABLE_VERSIONS`);
    ValueError for a body that does not hold a state."""
    try:
        raw = zstandard.ZstdDecompressor().decompress(body)
    except zstandard.ZstdError as error:
        raise ValueError(f"snapshot body is not zstandard: {error}") from None
    if len(raw) < SNAPSHOT_HEADER.size:
        raise ValueError("snapshot body is shorter than its header")
    (length,) = SNAPSHOT_HEADER.unpack_from(raw)
    start = SNAPSHOT_HEADER.size
    record = orjson.loads(memoryview(raw)[start : start + length])
    if version == SNAPSHOT_VERSION_ROWS:
        floats = np.frombuffer(raw, dtype="<f8", offset=start + length).tolist()
        return _decode_rows(record, floats)
    if version != SNAPSHOT_VERSION:
        raise ValueError(f"snapshot body version {version} is not supported")
    voxels, end = _voxel_map(raw, start + length, record.get("voxels"))
    floats_start = start + length
    float_count = (end - floats_start) // 8  # between the JSON and the voxel map
    # Copied out of the body: the tracks keep the block until their floats are read (packed,
    # `core.state.PackedFloats`), and should not keep the whole decompressed body with it.
    block = np.frombuffer(raw, dtype="<f8", count=float_count, offset=floats_start).astype(
        np.float64
    )
    columns = record["tracks"]
    if not isinstance(columns, dict) or columns.keys() != set(TRACK_FIELDS):
        raise ValueError("snapshot tracks do not hold the track fields")
    count = len(columns["track_id"])
    if any(len(columns[name]) != count for name in TRACK_FIELDS):
        raise ValueError("snapshot track columns differ in length")
    packed = _packed(block, columns.pop("recent_centers"), columns.pop("embedding_sum"))
    columns["existence_logodds"] = list(map(float, columns["existence_logodds"]))
    columns["center"] = list(map(tuple, columns["center"]))
    columns["extent"] = list(map(tuple, columns["extent"]))
    for name in ("published_center", "box"):
        columns[name] = [None if value is None else tuple(value) for value in columns[name]]
    names = tuple(columns)
    tracks = {}
    for row, floats in zip(zip(*columns.values(), strict=True), packed, strict=True):
        track = packed_track(zip(names, row, strict=True), floats)
        tracks[track.track_id] = track
    if len(tracks) != count:
        raise ValueError("snapshot tracks repeat an id")
    record["tracks"], record["voxels"] = [], []
    return dataclasses.replace(SceneState.from_dict(record), tracks=tracks, voxels=voxels)


def _voxel_map(raw: bytes, floats_start: int, shape: Any) -> tuple[VoxelMap, int]:
    """The voxel map stored at the end of a version 4 body, and where its float block ends."""
    if not isinstance(shape, dict) or shape.keys() != {"count", "width"}:
        raise ValueError("snapshot voxels do not hold the map's shape")
    count, width = shape["count"], shape["width"]
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in (count, width)):
        raise ValueError(f"snapshot voxel map of shape {count} x {width}")
    size = 8 * count * (2 + width)
    end = len(raw) - size
    if end < floats_start or (end - floats_start) % 8:
        raise ValueError(f"snapshot voxel map of {count} voxels does not fit the body")
    keys = np.frombuffer(raw, "<i8", count, end).astype(np.int64)
    counts = np.frombuffer(raw, "<i8", count, end + 8 * count).astype(np.int64)
    sums = np.frombuffer(raw, "<f8", count * width, end + 16 * count).astype(np.float64)
    if count > 1 and not bool((keys[1:] > keys[:-1]).all()):
        raise ValueError("snapshot voxel keys are not sorted and unique")
    return VoxelMap(keys, counts, sums.reshape(count, width)), end


def _packed(
    block: npt.NDArray[np.float64],
    center_counts: list[int | None],
    embedding_counts: list[int | None],
) -> list[PackedFloats]:
    """Each track's recent centers and embedding sum as spans of the float block (the centers
    of every track, then the embeddings), by their counts."""
    centers_total = 0
    for count in center_counts:
        if not isinstance(count, int) or isinstance(count, bool) or count < 0 or count % 3:
            raise ValueError(f"snapshot track with {count} center values")
        centers_total += count
    embedding_total = 0
    for count in embedding_counts:
        if count is not None and (
            not isinstance(count, int) or isinstance(count, bool) or count < 0
        ):
            raise ValueError(f"snapshot track with {count} embedding values")
        embedding_total += count or 0
    if centers_total + embedding_total != block.size:
        raise ValueError(f"snapshot float block of {block.size} values does not fit its tracks")
    packed = []
    point, position = 0, centers_total
    for centers, embedding in zip(center_counts, embedding_counts, strict=True):
        assert centers is not None  # checked above
        span = None
        if embedding is not None:
            span = (position, embedding)
            position += embedding
        packed.append(PackedFloats(block, (point, centers), span))
        point += centers
    return packed


def _decode_rows(record: dict[str, Any], floats: list[float]) -> SceneState:
    """A version 3 body: one JSON object per track."""
    tracks = record["tracks"]
    centers_total = sum(t["recent_centers"] or 0 for t in tracks)
    if centers_total % 3 or sum(t["embedding_sum"] or 0 for t in tracks) + centers_total != len(
        floats
    ):
        raise ValueError(f"snapshot float block of {len(floats)} values does not fit its tracks")
    coordinates = iter(floats[:centers_total])
    points = list(zip(coordinates, coordinates, coordinates, strict=True))  # in track order
    point, position = 0, centers_total
    for track in tracks:
        count = track["recent_centers"]
        if count is not None:
            if count < 0 or count % 3:
                raise ValueError(f"snapshot track {track['track_id']}: {count} center values")
            track["recent_centers"] = tuple(points[point : point + count // 3])
            point += count // 3
        count = track["embedding_sum"]
        if count is not None:
            track["embedding_sum"] = tuple(floats[position : position + count])
            position += count
    return SceneState.from_dict(record)
