"""Persistent false positives: a poster or a reflection that a detector reads as an object.

A phantom is a flat picture fixed in the world. From inside a cone of views around its normal it
is reported frame after frame with the object class it depicts, its mask is the picture's visible
part, and the depth behind that mask is whatever surface it hangs on, so a memory that trusts the
detector places an object there. Outside the cone (a reflection seen from the side) it is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.detectability import ViewFactors, view_factors
from sim.detector_settings import PhantomSpec
from sim.render import Render

PHANTOM_PREFIX = "phantom-"  # object_id of a phantom detection: no scenario object behind it
# The picture is hidden where a surface lies this much closer than the picture itself.
DEPTH_TOLERANCE_M = 0.05


@dataclass(frozen=True, eq=False)
class PhantomView:
    """A phantom as one camera sees it."""

    mask: np.ndarray  # bool (H, W): the unoccluded part of the picture
    factors: ViewFactors
    direction: np.ndarray  # unit vector from the picture to the camera, picture frame


def _axes(phantom: PhantomSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame unit normal, width axis and height axis of the picture."""
    normal = np.array([math.cos(phantom.facing), math.sin(phantom.facing), 0.0])
    across = np.array([-math.sin(phantom.facing), math.cos(phantom.facing), 0.0])
    return normal, across, np.array([0.0, 0.0, 1.0])


def phantom_corners(phantom: PhantomSpec) -> np.ndarray:
    """The picture's four world-frame corners."""
    _, across, up = _axes(phantom)
    center = np.asarray(phantom.at, dtype=np.float64)
    half_width, half_height = phantom.size[0] / 2, phantom.size[1] / 2
    return np.array(
        [
            center + sx * half_width * across + sy * half_height * up
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
    )


def _picture_mask(phantom: PhantomSpec, render: Render) -> np.ndarray:
    """Pixels whose ray hits the picture in front of the rendered surface (a raycast of one quad)."""
    camera, pose = render.camera, render.pose
    rotation, eye = pose[:3, :3], pose[:3, 3]
    normal, across, up = (axis @ rotation for axis in _axes(phantom))  # into the camera frame
    center = (np.asarray(phantom.at, dtype=np.float64) - eye) @ rotation
    mask = np.zeros((camera.height, camera.width), dtype=bool)
    local = (phantom_corners(phantom) - eye) @ rotation
    if (local[:, 2] <= 0.05).any():  # the picture reaches behind the camera: not framed
        return mask
    u = camera.fx * local[:, 0] / local[:, 2] + camera.cx
    v = camera.fy * local[:, 1] / local[:, 2] + camera.cy
    left, right = max(math.floor(u.min()), 0), min(math.ceil(u.max()) + 1, camera.width)
    top, bottom = max(math.floor(v.min()), 0), min(math.ceil(v.max()) + 1, camera.height)
    if left >= right or top >= bottom:
        return mask
    rows, cols = np.mgrid[top:bottom, left:right]
    rays = np.stack(
        ((cols - camera.cx) / camera.fx, (rows - camera.cy) / camera.fy, np.ones(cols.shape)), -1
    )
    facing = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(np.abs(facing) > 1e-9, float(center @ normal) / facing, -1.0)
    hits = rays * depth[..., None] - center
    on_picture = (
        (depth > camera.min_depth)
        & (np.abs(hits @ across) <= phantom.size[0] / 2)
        & (np.abs(hits @ up) <= phantom.size[1] / 2)
    )
    surface = render.depth[top:bottom, left:right]
    unhidden = (surface <= 0) | (surface >= depth - DEPTH_TOLERANCE_M)
    mask[top:bottom, left:right] = on_picture & unhidden
    return mask


def phantom_view(phantom: PhantomSpec, render: Render) -> PhantomView | None:
    """The phantom as this view shows it, None outside its cone or out of the picture."""
    normal, across, up = _axes(phantom)
    offset = render.pose[:3, 3] - np.asarray(phantom.at, dtype=np.float64)
    distance = float(np.linalg.norm(offset))
    if distance <= 0:
        return None
    direction = offset / distance
    if math.degrees(math.acos(min(1.0, float(direction @ normal)))) > phantom.cone_deg:
        return None
    mask = _picture_mask(phantom, render)
    if not mask.any():
        return None
    area = phantom.size[0] * phantom.size[1]
    factors = view_factors(
        phantom.at,
        phantom_corners(phantom),
        [(normal, area)],
        int(mask.sum()),
        render.camera,
        render.pose,
    )
    picture_frame = np.array([direction @ normal, direction @ across, direction @ up])
    return PhantomView(mask, factors, picture_frame)
