"""How detectable a thing is from one view, and a detector's luck that persists over frames.

Recall is the product of factors real detectors are known to have: mask area (small objects are
rarely found), range, grazing view of the object's main faces, truncation at the image border and
occlusion. Whether a detectable thing is reported is then decided by a latent Gaussian per thing
that drifts slowly (an AR(1) process): a thing missed in one frame is likely missed in the next,
while over a long run it is reported in exactly the fraction of views its recall says.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError
from scipy.special import ndtr

from sim.camera import CameraModel
from sim.detector_settings import RecallSpec
from sim.world import Box, box_corners

# Recall against mask area is a logistic in log-area; this is its width in natural-log units
# (a factor e^0.5 = 1.65 in area moves recall from 50 % to 73 % of its peak).
AREA_LOG_SOFTNESS = 0.5
# Range alone: 1 / (1 + (d / half_distance)^4), flat up close, falling off past half_distance.
DISTANCE_EXPONENT = 4.0
# Seen perfectly edge-on an object keeps this share of its recall (its outline still shows).
GRAZING_FLOOR = 0.25
# A face counts among an object's main faces when its area is at least this share of the largest.
MAIN_FACE_SHARE = 0.5
# Corners closer than this to the camera plane cannot be projected; the object is cut off.
NEAR_PLANE_M = 0.05
# An object partly behind the camera counts as at least this truncated.
BEHIND_CAMERA_TRUNCATION = 0.5


@dataclass(frozen=True)
class ViewFactors:
    """What a detector's chance depends on, for one thing in one view."""

    pixels: int  # visible mask area
    distance_m: float  # camera to the thing's center
    grazing_deg: float  # angle between the view ray and the best-seen main face (90: frontal)
    truncation: float  # share of the silhouette outside the image
    visible_fraction: float  # visible pixels / silhouette pixels inside the image (occlusion)


def box_faces(box: Box) -> list[tuple[np.ndarray, float]]:
    """(unit normal, area) of the three face pairs of a box."""
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    sx, sy, sz = box.size
    return [
        (np.array([cos_yaw, sin_yaw, 0.0]), sy * sz),
        (np.array([-sin_yaw, cos_yaw, 0.0]), sx * sz),
        (np.array([0.0, 0.0, 1.0]), sx * sy),
    ]


def _polygon_area(points: np.ndarray) -> float:
    """Shoelace area of a polygon given in order."""
    if len(points) < 3:
        return 0.0
    x, y = points[:, 0], points[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _clip_to_image(polygon: np.ndarray, width: int, height: int) -> np.ndarray:
    """Sutherland-Hodgman clipping of a convex polygon to the image rectangle."""
    edges = ((0, 0.0, 1.0), (0, float(width), -1.0), (1, 0.0, 1.0), (1, float(height), -1.0))
    points = polygon
    for axis, bound, sign in edges:
        if len(points) == 0:
            break
        kept = []
        for index in range(len(points)):
            current, following = points[index], points[(index + 1) % len(points)]
            current_in = sign * (current[axis] - bound) >= 0
            following_in = sign * (following[axis] - bound) >= 0
            if current_in:
                kept.append(current)
            if current_in != following_in:
                share = (bound - current[axis]) / (following[axis] - current[axis])
                kept.append(current + share * (following - current))
        points = np.array(kept)
    return points


def silhouette(corners: np.ndarray, camera: CameraModel, pose: np.ndarray) -> tuple[float, float]:
    """(silhouette area in pixels inside the image, share of the silhouette outside it)."""
    rotation, translation = pose[:3, :3], pose[:3, 3]
    local = (corners - translation) @ rotation  # world -> camera: R^T (p - t)
    front = local[local[:, 2] > NEAR_PLANE_M]
    if len(front) < 3:
        return 0.0, 1.0
    pixels = np.column_stack(
        (
            camera.fx * front[:, 0] / front[:, 2] + camera.cx + 0.5,
            camera.fy * front[:, 1] / front[:, 2] + camera.cy + 0.5,
        )
    )
    try:
        hull = pixels[ConvexHull(pixels).vertices]
    except QhullError:  # degenerate (edge-on plane): no area to speak of
        return 0.0, 0.0
    whole = _polygon_area(hull)
    inside = _polygon_area(_clip_to_image(hull, camera.width, camera.height))
    truncation = 1.0 - inside / whole if whole > 0 else 0.0
    if len(front) < len(corners):
        truncation = max(truncation, BEHIND_CAMERA_TRUNCATION)
    return inside, min(max(truncation, 0.0), 1.0)


def view_factors(
    center: Sequence[float],
    corners: np.ndarray,
    faces: Iterable[tuple[np.ndarray, float]],
    visible_pixels: int,
    camera: CameraModel,
    pose: np.ndarray,
) -> ViewFactors:
    """The factors of one thing (corners and faces in the world frame) seen from `pose`."""
    eye = pose[:3, 3]
    offset = eye - np.asarray(center, dtype=np.float64)
    distance = float(np.linalg.norm(offset))
    direction = offset / max(distance, 1e-9)
    face_list = list(faces)
    largest = max(area for _, area in face_list)
    grazing = max(
        math.degrees(math.asin(min(1.0, abs(float(direction @ normal)))))
        for normal, area in face_list
        if area >= MAIN_FACE_SHARE * largest
    )
    inside_area, truncation = silhouette(corners, camera, pose)
    visible_fraction = min(1.0, visible_pixels / inside_area) if inside_area > 0 else 1.0
    return ViewFactors(visible_pixels, distance, grazing, truncation, visible_fraction)


def box_view_factors(
    box: Box, visible_pixels: int, camera: CameraModel, pose: np.ndarray
) -> ViewFactors:
    """The view factors of a box-shaped object."""
    return view_factors(box.center, box_corners(box), box_faces(box), visible_pixels, camera, pose)


def _ramp(value: float, bounds: tuple[float, float]) -> float:
    """0 below bounds[0], 1 above bounds[1], linear between (a step when they coincide)."""
    low, high = bounds
    if high <= low:
        return 1.0 if value >= low else 0.0
    return min(max((value - low) / (high - low), 0.0), 1.0)


def recall_probability(factors: ViewFactors, spec: RecallSpec) -> float:
    """Chance that a detector reports this thing in this view."""
    if not spec.viewpoint:
        return spec.peak
    area = 1.0
    if spec.half_area_px > 0:
        log_ratio = math.log(max(factors.pixels, 1) / spec.half_area_px) / AREA_LOG_SOFTNESS
        area = 1.0 / (1.0 + math.exp(-log_ratio))
    distance = 1.0 / (1.0 + (factors.distance_m / spec.half_distance_m) ** DISTANCE_EXPONENT)
    grazing = GRAZING_FLOOR + (1.0 - GRAZING_FLOOR) * _ramp(factors.grazing_deg, spec.grazing_deg)
    truncation = max(0.0, 1.0 - factors.truncation / spec.truncation_zero)
    occlusion = _ramp(factors.visible_fraction, spec.visible_fraction)
    return float(spec.peak * area * distance * grazing * truncation * occlusion)


class DetectorLuck:
    """One latent N(0, 1) per thing, drifting as AR(1); a thing passes while Phi(z) < p.

    Every key is advanced every frame, seen or not, so the number of random draws never depends
    on what is visible and a (scenario, seed) pair always gives the same stream.
    """

    def __init__(self, keys: Sequence[str], correlation: float, rng: np.random.Generator) -> None:
        self.index = {key: position for position, key in enumerate(keys)}
        if len(self.index) != len(keys):
            raise ValueError("detector luck keys must be unique")
        self.correlation = correlation
        self.state = rng.standard_normal(len(keys))

    def step(self, rng: np.random.Generator) -> None:
        """Advance every thing's latent by one frame."""
        innovation = rng.standard_normal(len(self.state))
        self.state = self.correlation * self.state + math.sqrt(1.0 - self.correlation**2) * (
            innovation
        )

    def latent(self, key: str) -> float:
        """The thing's latent this frame (N(0, 1) over a long run)."""
        return float(self.state[self.index[key]])

    def passes(self, key: str, probability: float) -> bool:
        """Whether the thing is reported this frame, given its recall in this view."""
        return bool(ndtr(self.state[self.index[key]]) < probability)
