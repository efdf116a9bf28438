"""Candidate inspection views of one fixture and their cost J, equation (6) (section 3.4).

A candidate is a travel cell the robot can reach (connected known-free cells of the map
inflated by its radius) whose planar distance to the fixture's footprint is within the standoff.
The camera stands there at `camera_height_m`, turned towards the support's centre and tilted at
it (within the head's tilt range). A view is feasible when the support's centre is in range,
inside the image minus its margin and in line of sight on the map, and the projected coverage
of the support surface reaches `min_coverage`; views near a failed one are excluded. Among
feasible views the controller minimises

    J(v, i) = |d_foot(v, i) - d_pref| + 0.08 D_t(v) - 0.20 min(Clr(v), 1 m)
              + 4 [1 - Cov(v, i)] + P_margin(v, i).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from core.navigation import Navigation
from core.params import PlannerParams
from core.state import Track
from core.values import ViewPose

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
COST_TERMS = ("standoff", "travel", "clearance", "coverage", "margin")


@dataclass(frozen=True)
class View:
    """One feasible view of a fixture with its cost J and J's terms."""

    pose: ViewPose  # where to stand, facing the support's centre
    pitch: float  # camera tilt, radians (negative looks down)
    standoff_m: float  # d_foot(v, i)
    travel_m: float  # D_t(v)
    clearance_m: float  # Clr(v)
    coverage: float  # Cov(v, i)
    cost: float  # J(v, i)
    cost_terms: dict[str, float]  # the five terms of J, summing to it


@dataclass(frozen=True)
class Support:
    """The fixture's support surface: the top face of its box."""

    center: tuple[float, float, float]
    footprint: tuple[float, float, float, float]  # x min, y min, x max, y max

    @classmethod
    def of(cls, fixture: Track) -> Support:
        """The top face of the fixture's stored box."""
        (x, y, z), (dx, dy, dz) = fixture.center, fixture.extent
        return cls((x, y, z + dz / 2), (x - dx / 2, y - dy / 2, x + dx / 2, y + dy / 2))

    def samples(self, per_axis: int) -> FloatArray:
        """An n x n grid of points on the face (cell centres), (n*n, 3)."""
        x0, y0, x1, y1 = self.footprint
        u = (np.arange(per_axis) + 0.5) / per_axis
        xs, ys = np.meshgrid(x0 + (x1 - x0) * u, y0 + (y1 - y0) * u, indexing="ij")
        return np.column_stack((xs.ravel(), ys.ravel(), np.full(xs.size, self.center[2])))

    def corners(self) -> FloatArray:
        """The face's four corners, (4, 3)."""
        x0, y0, x1, y1 = self.footprint
        z = self.center[2]
        return np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])

    def distance(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """d_foot: planar distance to the footprint (0 inside it)."""
        x0, y0, x1, y1 = self.footprint
        dx = np.maximum(np.maximum(x0 - x, x - x1), 0.0)
        dy = np.maximum(np.maximum(y0 - y, y - y1), 0.0)
        result: FloatArray = np.hypot(dx, dy)
        return result


def view_cost(
    standoff_m: float | FloatArray,
    travel_m: float | FloatArray,
    clearance_m: float | FloatArray,
    coverage: float | FloatArray,
    margin_penalty: float | FloatArray,
    params: PlannerParams,
) -> dict[str, FloatArray]:
    """The five terms of J (equation (6)); J is their sum."""
    return {
        "standoff": np.abs(np.asarray(standoff_m) - params.preferred_standoff_m),
        "travel": params.travel_weight * np.asarray(travel_m),
        "clearance": -params.clearance_weight
        * np.minimum(np.asarray(clearance_m), params.clearance_cap_m),
        "coverage": params.coverage_weight * (1.0 - np.asarray(coverage)),
        "margin": np.asarray(margin_penalty, dtype=np.float64),
    }


@dataclass(frozen=True)
class Projection:
    """Points seen from candidate cameras: in front and in range, image coordinates scaled so
    the image border is at +-1."""

    in_front: BoolArray  # (n, m)
    in_range: BoolArray
    u: FloatArray
    v: FloatArray


def project(
    cameras: FloatArray, yaw: FloatArray, pitch: FloatArray, points: FloatArray, p: PlannerParams
) -> Projection:
    """Project (m, 3) world points into n cameras at (n, 3) positions with yaw and pitch."""
    cos_p, sin_p = np.cos(pitch)[:, None], np.sin(pitch)[:, None]
    cos_y, sin_y = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    d = points[None, :, :] - cameras[:, None, :]  # (n, m, 3)
    forward = cos_p * cos_y * d[..., 0] + cos_p * sin_y * d[..., 1] + sin_p * d[..., 2]
    right = sin_y * d[..., 0] - cos_y * d[..., 1]
    # down = forward x right
    down = sin_p * cos_y * d[..., 0] + sin_p * sin_y * d[..., 1] - cos_p * d[..., 2]
    in_front = forward > 1e-6
    safe = np.where(in_front, forward, 1.0)
    u = right / safe / math.tan(math.radians(p.horizontal_fov_deg) / 2)
    v = down / safe / math.tan(math.radians(p.vertical_fov_deg) / 2)
    distance = np.linalg.norm(d, axis=2)
    in_range = (distance >= p.min_view_range_m) & (distance <= p.max_view_range_m)
    return Projection(in_front, in_range, u, v)


def feasible_views(
    navigation: Navigation,
    fixture: Track,
    failed: Sequence[ViewPose],
    params: PlannerParams,
    only: tuple[float, float] | None = None,
) -> list[View]:
    """Every feasible view of the fixture, cheapest first (ties by position); `only` evaluates
    just the travel cell holding that point (a locked view, re-checked)."""
    candidates = _candidates(navigation, fixture, failed, params, only)
    if candidates is None:
        return []
    views = candidates.sighted(np.arange(candidates.size))
    return sorted(views, key=_order)


def best_view(
    navigation: Navigation,
    fixture: Track,
    failed: Sequence[ViewPose],
    params: PlannerParams,
    only: tuple[float, float] | None = None,
) -> View | None:
    """The feasible view minimising J (ties by position), or None: `feasible_views(...)[0]`.

    Line of sight is the costly check, and it can only lower the coverage, so J is bounded
    below by its value with every in-image support point taken as seen: candidates are
    checked in the order of that bound until the best J found is below the next bound.
    """
    candidates = _candidates(navigation, fixture, failed, params, only)
    if candidates is None:
        return None
    order = np.lexsort((candidates.y, candidates.x, candidates.lower))
    order = order[candidates.possible[order]]
    best: View | None = None
    for start in range(0, order.size, _CHUNK):
        if best is not None and best.cost < candidates.lower[order[start]]:
            break
        for view in candidates.sighted(order[start : start + _CHUNK]):
            if best is None or _order(view) < _order(best):
                best = view
    return best


_CHUNK = 32  # candidates checked for line of sight at a time


def _order(view: View) -> tuple[float, float, float]:
    return (view.cost, view.pose.x, view.pose.y)


def _candidates(
    navigation: Navigation,
    fixture: Track,
    failed: Sequence[ViewPose],
    params: PlannerParams,
    only: tuple[float, float] | None,
) -> Candidates | None:
    """Reachable known-free travel cells within the standoff, away from failed views."""
    support = Support.of(fixture)
    xs, ys = navigation.travel_centers()
    travel = navigation.travel
    if only is not None:
        cell = navigation.travel_cell_of(*only)
        if cell is None:
            return None
        pick = np.zeros(travel.shape, dtype=bool)
        pick[cell] = True
    else:
        pick = np.ones(travel.shape, dtype=bool)
    standoff = support.distance(xs, ys)
    pick &= np.isfinite(travel) & navigation.known_ok  # connected known-free cells
    pick &= (standoff >= params.min_standoff_m) & (standoff <= params.max_standoff_m)
    rows, cols = np.nonzero(pick)
    if rows.size > params.max_candidate_views:  # a deterministic stride over the ring
        keep = np.arange(0, rows.size, math.ceil(rows.size / params.max_candidate_views))
        rows, cols = rows[keep], cols[keep]
    x, y = xs[rows, cols], ys[rows, cols]
    if failed:
        near = np.zeros(x.shape, dtype=bool)
        for view in failed:
            near |= np.hypot(x - view.x, y - view.y) < params.failed_view_radius_m
        x, y, rows, cols = x[~near], y[~near], rows[~near], cols[~near]
    if x.size == 0:
        return None
    return Candidates(navigation, support, x, y, travel[rows, cols], standoff[rows, cols], params)


class Candidates:
    """Candidate views of one fixture: what the camera model says of each (projection, range,
    image margin, clearance), and the bound on J before line of sight."""

    def __init__(
        self,
        navigation: Navigation,
        support: Support,
        x: FloatArray,
        y: FloatArray,
        travel: FloatArray,
        standoff: FloatArray,
        params: PlannerParams,
    ) -> None:
        self.navigation, self.support, self.params = navigation, support, params
        self.x, self.y, self.travel, self.standoff = x, y, travel, standoff
        self.size = x.size
        center = np.asarray(support.center)
        cameras = np.column_stack((x, y, np.full(x.size, params.camera_height_m)))
        self.yaw = np.arctan2(center[1] - y, center[0] - x)
        horizontal = np.hypot(center[0] - x, center[1] - y)
        self.pitch = np.clip(
            np.arctan2(center[2] - params.camera_height_m, horizontal),
            math.radians(params.min_pitch_deg),
            math.radians(params.max_pitch_deg),
        )
        inner = 1.0 - params.image_margin
        # The support's centre: in range and inside the image minus its margin.
        middle = project(cameras, self.yaw, self.pitch, center[None, :], params)
        self.center_ok = (
            middle.in_front[:, 0]
            & middle.in_range[:, 0]
            & (np.abs(middle.u[:, 0]) <= inner)
            & (np.abs(middle.v[:, 0]) <= inner)
        )
        # Support samples in front, in range and inside the image minus the margin.
        self.samples = support.samples(params.support_samples_per_axis)
        seen = project(cameras, self.yaw, self.pitch, self.samples, params)
        self.in_image = seen.in_front & seen.in_range
        self.in_image &= (np.abs(seen.u) <= inner) & (np.abs(seen.v) <= inner)
        # P_margin: how far the farthest corner intrudes into the margin (or beyond the border).
        corners = project(cameras, self.yaw, self.pitch, support.corners(), params)
        border = np.where(
            corners.in_front, 1.0 - np.maximum(np.abs(corners.u), np.abs(corners.v)), -1.0
        ).min(axis=1)
        if params.image_margin > 0:
            intrusion = np.clip((params.image_margin - border) / params.image_margin, 0.0, 1.0)
        else:
            intrusion = (border < 0).astype(np.float64)
        self.margin = params.margin_penalty_weight * intrusion
        self.clearance = navigation.clearance_at(x, y)
        # Line of sight only removes support points: J with all in-image points seen is a
        # lower bound (the same sum, term by term, with a coverage at least as high).
        upper_coverage = self.in_image.mean(axis=1)
        self.lower = self._costs(upper_coverage)[1]
        self.possible = self.center_ok & (upper_coverage >= params.min_coverage)

    def _costs(
        self, coverage: FloatArray, index: Any = slice(None)
    ) -> tuple[dict[str, FloatArray], FloatArray]:
        terms = view_cost(
            self.standoff[index],
            self.travel[index],
            self.clearance[index],
            coverage,
            self.margin[index],
            self.params,
        )
        return terms, np.sum([terms[name] for name in COST_TERMS], axis=0)

    def sighted(self, index: npt.NDArray[np.intp]) -> list[View]:
        """The feasible views among candidates `index`, with line of sight checked."""
        index = index[self.possible[index]]
        if index.size == 0:
            return []
        nav, support = self.navigation, self.support
        ignore = _grown(support.footprint, self.params.own_footprint_margin_m)
        starts = np.column_stack((self.x[index], self.y[index]))
        center = np.tile(np.asarray(support.center[:2]), (index.size, 1))
        feasible = nav.line_of_sight(starts, center, ignore)
        count = self.samples.shape[0]
        sight = nav.line_of_sight(
            np.repeat(starts, count, axis=0), np.tile(self.samples[:, :2], (index.size, 1)), ignore
        ).reshape(index.size, count)
        coverage = (self.in_image[index] & sight).mean(axis=1)
        feasible &= coverage >= self.params.min_coverage
        terms, cost = self._costs(coverage, index)
        return [
            View(
                pose=ViewPose(x=float(self.x[i]), y=float(self.y[i]), yaw=float(self.yaw[i])),
                pitch=float(self.pitch[i]),
                standoff_m=float(self.standoff[i]),
                travel_m=float(self.travel[i]),
                clearance_m=float(min(self.clearance[i], 1e6)),
                coverage=float(coverage[j]),
                cost=float(cost[j]),
                cost_terms={name: float(terms[name][j]) for name in COST_TERMS},
            )
            for j, i in enumerate(index)
            if feasible[j]
        ]


def _grown(
    box: tuple[float, float, float, float], margin: float
) -> tuple[float, float, float, float]:
    return (box[0] - margin, box[1] - margin, box[2] + margin, box[3] + margin)
