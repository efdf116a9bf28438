"""Detector mistakes beyond missed and leaky masks: confused labels and false-positive blobs."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from sim.detector import SimDetection
from sim.render import Render
from sim.world import World

FALSE_POSITIVE_PREFIX = "fp-"  # object_id of a false positive: no scenario object behind it
BLOB_AREA_RANGE = (200.0, 800.0)  # pixels of a false-positive ellipse before image clipping
BLOB_AXIS_RATIO_RANGE = (0.5, 1.0)
SURFACE_TOLERANCE_M = 0.03  # a pixel is on a surface when its height is this close to it


def confuse_labels(
    detections: Sequence[SimDetection],
    labels: Sequence[str],
    rate: float,
    rng: np.random.Generator,
) -> list[SimDetection]:
    """Each detection keeps its label, or with probability `rate` takes another scenario label."""
    confused = []
    for detection in detections:
        # One draw per detection whatever happens, so the stream stays aligned across rates.
        draw = rng.random()
        others = [label for label in labels if label != detection.label]
        if draw < rate and others:
            label = others[int(rng.integers(len(others)))]
            detection = dataclasses.replace(detection, label=label)
        confused.append(detection)
    return confused


def pixel_heights(render: Render) -> np.ndarray:
    """World z of every pixel's surface point (NaN where the depth is invalid)."""
    camera, pose = render.camera, render.pose
    cols = (np.arange(camera.width) - camera.cx) / camera.fx
    rows = (np.arange(camera.height) - camera.cy) / camera.fy
    # z_world = depth * (R[2] . (x_n, y_n, 1)) + t_z; separable in rows and columns.
    slope = pose[2, 0] * cols[None, :] + pose[2, 1] * rows[:, None] + pose[2, 2]
    heights = render.depth * slope + pose[2, 3]
    return np.where(render.depth > 0, heights, np.nan)


def surface_regions(render: Render, world: World) -> list[np.ndarray]:
    """Flat pixel indices of each visible fixture top, then of the visible floor (z = 0)."""
    heights = pixel_heights(render)
    regions = []
    for index, fixture in enumerate(world.fixtures):
        on_top = (render.fixture_instance == index) & (
            np.abs(heights - fixture.top_z) < SURFACE_TOLERANCE_M
        )
        regions.append(np.flatnonzero(on_top))
    floor = (
        (render.instance < 0)
        & (render.fixture_instance < 0)
        & (np.abs(heights) < SURFACE_TOLERANCE_M)
    )
    regions.append(np.flatnonzero(floor))
    return [region for region in regions if region.size > 0]


def ellipse_mask(
    shape: tuple[int, int], center: tuple[int, int], area: float, ratio: float, angle: float
) -> np.ndarray:
    """A filled ellipse of about `area` pixels around (row, col), clipped to the image."""
    major = math.sqrt(area / (math.pi * ratio))
    minor = major * ratio
    reach = math.ceil(major) + 1
    row, col = center
    top, bottom = max(row - reach, 0), min(row + reach + 1, shape[0])
    left, right = max(col - reach, 0), min(col + reach + 1, shape[1])
    rows, cols = np.mgrid[top:bottom, left:right]
    dy, dx = rows - row, cols - col
    along = dx * math.cos(angle) + dy * math.sin(angle)
    across = -dx * math.sin(angle) + dy * math.cos(angle)
    mask = np.zeros(shape, dtype=bool)
    mask[top:bottom, left:right] = (along / major) ** 2 + (across / minor) ** 2 <= 1.0
    return mask


def false_positives(
    render: Render,
    world: World,
    rng: np.random.Generator,
    *,
    rate: float,
    labels: Sequence[str],
    frame_index: int,
    score: float,
    embedding_dim: int | None,
) -> list[SimDetection]:
    """Poisson(`rate`) blobs on visible fixture tops or floor, with scenario labels and noise."""
    count = int(rng.poisson(rate)) if rate > 0 else 0
    if count == 0 or not labels:
        return []
    regions = surface_regions(render, world)
    if not regions:
        return []
    detections = []
    for number in range(count):
        region = regions[int(rng.integers(len(regions)))]
        pixel = int(region[int(rng.integers(region.size))])
        center = divmod(pixel, render.camera.width)
        area = rng.uniform(*BLOB_AREA_RANGE)
        ratio = rng.uniform(*BLOB_AXIS_RATIO_RANGE)
        angle = rng.uniform(0.0, math.pi)
        mask = ellipse_mask(render.depth.shape, center, area, ratio, angle)
        label = labels[int(rng.integers(len(labels)))]
        embedding = None
        if embedding_dim is not None:
            embedding = rng.standard_normal(embedding_dim)
            embedding /= np.linalg.norm(embedding)
        object_id = f"{FALSE_POSITIVE_PREFIX}{frame_index}-{number}"
        detections.append(SimDetection(object_id, label, score, mask, embedding))
    return detections
