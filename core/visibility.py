"""The geometric visibility gate V_i(t) of equation (3) (section 3.3), and when a miss counts.

A track unmatched in a frame is a visible miss only when its stored box was observable there:
at least two box samples in the valid range, inside the image, with valid depth in a 5x5 window
and nothing closer in front (d_meas + 0.15 m >= d_expected). We add the missed-detection
condition: the part of the box that was observable must be large enough in the image that the
detector would have reported the object had it been there. A sliver at the image border, a
grazing view or a far object is not evidence of absence: detectors do not report those.
And the empty-place condition: the depth must show the place empty, the ray to the object's
centre meeting its first surface behind that centre. An object still there but missed by the
detector shows its own surface in front of its centre: that is the detector's miss, not the
object's.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from core.compiled import compiled
from core.geometry import box_samples, project, world_to_camera
from core.observation import Frame
from core.params import Params, VisibilityParams
from core.rules import UpdateRules
from core.state import SceneState

FloatArray = npt.NDArray[np.float64]
MissEvidence = Literal["visible", "free_space"]


@dataclass(frozen=True)
class Sighting:
    """How well one frame showed a stored box."""

    passed: int  # samples that passed the gate
    expected_fraction: float  # share of the image the observable part of the box covers
    in_image_share: float = 1.0  # share of the box's projected extent inside the image
    # The depth at the object's centre lies behind it: the place is seen empty (no object there).
    center_empty: bool = True
    frame_id: str = ""


def observable(sighting: Sighting, params: VisibilityParams, gate: bool = True) -> bool:
    """V_i(t) = 1: at least two samples pass, and (with the gate) the observable part is
    large enough to be detected and, unless the paper's gate is asked for, the depth shows the
    place empty."""
    return sighting.passed >= params.min_samples_passed and (
        not gate
        or (
            sighting.expected_fraction >= params.min_expected_image_fraction
            and sighting.in_image_share >= params.min_in_image_share
            and (sighting.center_empty or not params.miss_requires_empty_center)
        )
    )


@dataclass(frozen=True)
class BatchVisibility:
    """V_i(t) for one batch: what its frames showed of each live track's stored box."""

    best: Mapping[str, Sighting]  # per track shown at all: the sighting that stands for the batch
    visible: frozenset[str]  # V_i(t) = 1 under the update rules: unmatched, a visible miss
    # Per frame: the tracks whose place the frames up to it showed (the paper's gate), which
    # the unique-class fallback counts as a look at an empty place when nothing matched them.
    shown: tuple[frozenset[str], ...]


def batch_visibility(
    state: SceneState, frames: Sequence[Frame], params: Params, rules: UpdateRules
) -> BatchVisibility:
    """The gate over a batch's frames, for every live track that could be in view.

    Removed and rejected tracks get no negative evidence, and neither do fine nodes held by the
    capture ledger: only a capture of their fixture speaks of them (section 3.3).
    """
    arrays = state.arrays
    live = ~arrays.gone & ~arrays.captured
    best: dict[str, Sighting] = {}
    shown: list[frozenset[str]] = []
    # DynaMem's clearing rule is per voxel of the object itself: its samples are the latest
    # observed box (the object's own points), not the union of every view, which a bleeding
    # mask grows over the background around it.
    per_voxel = rules.miss_evidence == "free_space"
    centers = arrays.centers if per_voxel else arrays.box_centers
    extents = arrays.extents if per_voxel else arrays.box_extents
    for frame in frames:
        rows = in_view_rows(centers, extents, frame, params.visibility)
        rows = rows[live[rows]]
        columns = sample_columns(
            centers[rows],
            extents[rows],
            frame,
            params.visibility,
            rules.visibility_gate,
            rules.miss_evidence,
            probes=arrays.centers[rows],
        )
        for index, sighting in columns.shown(frame.frame_id):
            track_id = arrays.track_ids[int(rows[index])]
            held = best.get(track_id)
            if held is None or _rank(sighting, params.visibility, rules.visibility_gate) > _rank(
                held, params.visibility, rules.visibility_gate
            ):
                best[track_id] = sighting
        shown.append(frozenset(t for t, s in best.items() if observable(s, params.visibility)))
    visible = frozenset(
        t for t, s in best.items() if observable(s, params.visibility, rules.visibility_gate)
    )
    return BatchVisibility(best, visible, tuple(shown))


def _rank(sighting: Sighting, params: VisibilityParams, gate: bool) -> tuple[bool, int, float]:
    """Which of a batch's sightings of a track stands for the batch: one that would count a miss
    first, then the one showing more of the box."""
    return (observable(sighting, params, gate), sighting.passed, sighting.expected_fraction)


def in_view_rows(
    centers: FloatArray, extents: FloatArray, frame: Frame, params: VisibilityParams
) -> npt.NDArray[np.intp]:
    """Rows whose box may reach the camera's range in front of it (a cheap cull before sampling)."""
    if centers.shape[0] == 0:
        return np.zeros(0, dtype=np.intp)
    depth = world_to_camera(centers, frame.pose)[:, 2]
    reach = 0.5 * np.linalg.norm(extents, axis=1)
    return np.flatnonzero(
        (depth + reach >= params.min_range_m) & (depth - reach <= params.max_range_m)
    )


class SampleColumns(NamedTuple):
    """Per stored box: samples passed, observable image share, share in the image, and
    whether the place is seen empty (one array each)."""

    passed: npt.NDArray[np.intp]
    fraction: FloatArray
    in_image_share: FloatArray
    empty: npt.NDArray[np.bool_]

    def sighting(self, index: int, frame_id: str = "") -> Sighting:
        """The sighting of the box at `index`, naming its frame."""
        return Sighting(
            int(self.passed[index]),
            float(self.fraction[index]),
            float(self.in_image_share[index]),
            bool(self.empty[index]),
            frame_id,
        )

    def sightings(self, frame_id: str = "") -> list[Sighting]:
        """One sighting per box, in order."""
        return [self.sighting(index, frame_id) for index in range(len(self.passed))]

    def shown(self, frame_id: str) -> Iterator[tuple[int, Sighting]]:
        """(index, sighting) of the boxes with a sample passed (the only ones a batch keeps)."""
        passed, fraction = self.passed.tolist(), self.fraction.tolist()
        in_image, empty = self.in_image_share.tolist(), self.empty.tolist()
        for index in np.flatnonzero(self.passed).tolist():
            yield (
                index,
                Sighting(passed[index], fraction[index], in_image[index], empty[index], frame_id),
            )


def sample_columns(
    centers: FloatArray,
    extents: FloatArray,
    frame: Frame,
    params: VisibilityParams,
    occlusion_test: bool = True,
    miss_evidence: MissEvidence = "visible",
    probes: FloatArray | None = None,
) -> SampleColumns:
    """For each stored box: its samples that pass in `frame`, and its observable image share.

    Whether the place is seen empty is tested along the ray to each box's `probes` point (the
    object's own center mu_i; the box's centre when not given).

    A sample passes when it lies in the valid camera range, projects inside the image, has
    valid depth in a 5x5 window, and d_meas + 0.15 m >= d_expected (no closer surface hides
    it). With `miss_evidence="free_space"` (a DynaMem-like rule) a sample passes only when the
    depth shows free space at it: d_meas > d_expected + 0.15 m.
    """
    count = centers.shape[0]
    if count == 0:
        return SampleColumns(np.zeros(0, np.intp), np.zeros(0), np.zeros(0), np.zeros(0, np.bool_))
    per_track = params.box_samples_per_axis**3
    rows = _within_range(centers, extents, frame.pose, params)
    samples = world_to_camera(
        box_samples(centers[rows], extents[rows], params.box_samples_per_axis).reshape(-1, 3),
        frame.pose,
    )
    expected = samples[:, 2]
    in_range = (expected >= params.min_range_m) & (expected <= params.max_range_m)
    candidate = np.flatnonzero(in_range)
    u, v = project(samples[candidate], frame.intrinsics)
    width, height = frame.intrinsics.width, frame.intrinsics.height
    owner = rows[candidate // per_track]
    full_area = _bbox_area(owner, u, v, count)  # the box's projection, unclipped
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    candidate, u, v, owner = candidate[inside], u[inside], v[inside], owner[inside]
    ok = np.ones(candidate.size, dtype=bool)
    if occlusion_test and candidate.size:
        measured = _window_depth(
            frame.depth, np.rint(u).astype(np.intp), np.rint(v).astype(np.intp), params
        )
        if miss_evidence == "free_space":
            ok = (measured > 0) & (measured > expected[candidate] + params.occlusion_margin_m)
        else:
            ok = (measured > 0) & (measured + params.occlusion_margin_m >= expected[candidate])
    passed = np.bincount(owner[ok], minlength=count)
    in_image = np.bincount(owner, minlength=count)
    if miss_evidence == "free_space":
        # Free space must be what the depth shows of the box, not a few samples at its
        # silhouette where the window reaches the wall behind an object still there.
        passed = np.where(2 * passed >= in_image, passed, 0)
    # The observable part's image area: the box's projected extent inside the image, times the
    # share of its in-image samples that passed; and how much of its projection is in the image.
    area = _bbox_area(owner, u, v, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(in_image > 0, passed / np.maximum(in_image, 1), 0.0)
        in_image_share = np.where(full_area > 0, area / np.maximum(full_area, 1e-9), 0.0)
    fraction = area * share / (width * height)
    # The free-space rule is its own test of an empty place; without the occlusion test there
    # is no depth test at all.
    if occlusion_test and miss_evidence == "visible":
        empty = _center_empty(centers if probes is None else probes, frame, params)
    else:
        empty = np.ones(count, dtype=np.bool_)
    return SampleColumns(passed, fraction, in_image_share, empty)


def _within_range(
    centers: FloatArray, extents: FloatArray, pose: FloatArray, params: VisibilityParams
) -> npt.NDArray[np.intp]:
    """The boxes some sample of which may lie in the camera's range: the others' samples are
    all nearer than `min_range_m` or farther than `max_range_m`, so they pass nothing and
    project nowhere, and their samples need not be made. A sample's depth lies within half the
    box's extent, measured along the optical axis, of its centre's; the bound is widened by
    far more than the rounding of either, so no box a sample of which is in range is left out."""
    axis = pose[:3, 2]  # the camera's z axis in the world: depth = (p - t) . axis
    depth = (centers - pose[:3, 3]) @ axis
    reach = 0.5 * np.abs(extents) @ np.abs(axis)
    slack = 1e-6 + 1e-9 * (np.abs(depth) + reach)
    near_enough = depth - reach - slack <= params.max_range_m
    far_enough = depth + reach + slack >= params.min_range_m
    return np.flatnonzero(near_enough & far_enough)


def _center_empty(
    centers: FloatArray, frame: Frame, params: VisibilityParams
) -> npt.NDArray[np.bool_]:
    """Per object: its centre projects into the image, in range, and the first surface along that
    ray lies at least `empty_center_margin_m` behind it."""
    points = world_to_camera(centers, frame.pose)
    expected = points[:, 2]
    empty = np.zeros(centers.shape[0], dtype=np.bool_)
    rows = np.flatnonzero((expected >= params.min_range_m) & (expected <= params.max_range_m))
    if rows.size == 0:
        return empty
    u, v = project(points[rows], frame.intrinsics)
    width, height = frame.intrinsics.width, frame.intrinsics.height
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    rows, u, v = rows[inside], u[inside], v[inside]
    if rows.size == 0:
        return empty
    measured = _window_depth(
        frame.depth, np.rint(u).astype(np.intp), np.rint(v).astype(np.intp), params
    )
    empty[rows] = (measured > 0) & (measured >= expected[rows] + params.empty_center_margin_m)
    return empty


@compiled()
def _bbox_area(
    owner: npt.NDArray[np.intp], u: FloatArray, v: FloatArray, count: int
) -> FloatArray:  # pragma: no cover - compiled
    """Per box, the area in pixels of the bounding box of its projected samples (0 when none,
    or when a sample's coordinate is NaN, as numpy's minimum.at made it): each owner's extreme
    u and v in one pass, then (du + 1) * (dv + 1)."""
    low_u, high_u = np.full(count, np.inf), np.full(count, -np.inf)
    low_v, high_v = np.full(count, np.inf), np.full(count, -np.inf)
    for index in range(owner.size):
        box = owner[index]
        low_u[box] = np.minimum(low_u[box], u[index])  # NaN propagates, as in minimum.at
        high_u[box] = np.maximum(high_u[box], u[index])
        low_v[box] = np.minimum(low_v[box], v[index])
        high_v[box] = np.maximum(high_v[box], v[index])
    area = np.zeros(count)
    for box in range(count):
        if np.isfinite(low_u[box]):
            area[box] = (high_u[box] - low_u[box] + 1) * (high_v[box] - low_v[box] + 1)
    return area


def _window_depth(
    depth: npt.NDArray[np.float32],
    u: npt.NDArray[np.intp],
    v: npt.NDArray[np.intp],
    params: VisibilityParams,
) -> FloatArray:
    """Median of the valid depths in the window around each pixel; 0 where none is valid.

    A window reaching past the image's edge repeats the edge's pixels (the coordinates are
    clipped). The windows are read in one compiled pass, invalid depths as +inf so that they
    sort last, and sorted by numpy in the image's own precision (compared as float64, as the
    limits are: the values and their order are the same).
    """
    window, counts = _windows(
        depth,
        u,
        v,
        params.depth_window_px // 2,
        float(params.min_range_m),
        float(params.max_range_m),
    )
    window.sort(axis=1)
    rows_index = np.arange(len(u))
    upper = window[rows_index, counts // 2].astype(np.float64)
    lower = window[rows_index, np.maximum(counts - 1, 0) // 2].astype(np.float64)
    measured: FloatArray = np.where(counts > 0, 0.5 * (upper + lower), 0.0)
    return measured


@compiled()
def _windows(
    depth: npt.NDArray[np.float32],
    u: npt.NDArray[np.intp],
    v: npt.NDArray[np.intp],
    half: int,
    low: float,
    high: float,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.intp]]:  # pragma: no cover - compiled
    """Each pixel's window of depths (row-major, clamped at the edges), the ones outside
    [low, high] as +inf, and how many are inside."""
    height, width = depth.shape
    side = 2 * half + 1
    window = np.empty((u.size, side * side), depth.dtype)
    counts = np.zeros(u.size, np.intp)
    for index in range(u.size):
        slot = 0
        for row in range(v[index] - half, v[index] + half + 1):
            clamped = min(max(row, 0), height - 1)
            for col in range(u[index] - half, u[index] + half + 1):
                value = depth[clamped, min(max(col, 0), width - 1)]
                if np.float64(value) >= low and np.float64(value) <= high:
                    window[index, slot] = value
                    counts[index] += 1
                else:
                    window[index, slot] = np.inf
                slot += 1
    return window, counts
