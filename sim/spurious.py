"""Detector mistakes beyond missed and leaky masks: confused labels, false-positive blobs, and
the places a fixture segmenter keeps hallucinating furniture (spurious fixture sites)."""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.detector import DISTRACTOR_SCORE_RANGE, TRUE_CLASS_SCORE, SimDetection
from sim.render import Render
from sim.world import Box, World

FALSE_POSITIVE_PREFIX = "fp-"  # object_id of a false positive: no scenario object behind it
BLOB_AREA_RANGE = (200.0, 800.0)  # pixels of a false-positive ellipse before image clipping
BLOB_AXIS_RATIO_RANGE = (0.5, 1.0)
SURFACE_TOLERANCE_M = 0.03  # a pixel is on a surface when its height is this close to it

SPURIOUS_FIXTURE_PREFIX = "spurious-"  # object_id of a hallucinated fixture mask
# What a furniture-prompted segmenter reads into each kind of place (our choice of examples):
# a stretch of wall (a door, a radiator, a window sill, a backsplash), a rug, a chair or an
# armchair, and something tall (a plant column, a coat stand).
SITE_LABELS = {
    "wall": ("cabinet", "shelf", "counter"),
    "floor": ("bed", "table"),
    "low": ("sofa", "table"),
    "tall": ("shelf", "cabinet"),
}
# Of the sites of a synthetic room, these shares are on walls and on the floor; the rest are
# occluders (chairs), when the room has any. A recorded room has no modelled walls: its wall
# share goes to bands of real surface at furniture height.
WALL_SHARE, FLOOR_SHARE = 0.5, 0.3
SITE_DEPTH_M = 0.10  # a region site spans this much across the surface it lies on
TALL_OCCLUDER_M = 1.1  # an occluder taller than this reads as a shelf, not a seat
SPURIOUS_TOP_SCORE = TRUE_CLASS_SCORE - 0.05  # hallucinations score a little under true pieces
SPURIOUS_RIVAL_GAP = 0.08  # the second class of a site's list scores this much lower


@dataclass(frozen=True)
class SpuriousSite:
    """A place the segmenter reads as furniture: a region of the scene, or an occluder."""

    index: int
    kind: str  # "wall", "floor", "band", "low" or "tall"
    labels: tuple[str, str]  # the class it is read as, then its runner-up
    region: Box | None  # world-frame box whose background surface makes the mask
    occluder: str | None = None  # the occluder (a chair) whose pixels make the mask

    @property
    def id(self) -> str:
        """The object_id of its detections (ground truth side only)."""
        return f"{SPURIOUS_FIXTURE_PREFIX}{self.index}"


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


def _site_area(room_size: Sequence[float], fixtures: Sequence[Box]) -> tuple[float, ...]:
    """x0, y0, x1, y1 of where sites may lie: the room, else the fixtures' area grown by 1 m."""
    if room_size[0] > 0 and room_size[1] > 0:
        return 0.0, 0.0, float(room_size[0]), float(room_size[1])
    xs = [f.center[0] + sign * max(f.size[:2]) / 2 for f in fixtures for sign in (-1, 1)]
    ys = [f.center[1] + sign * max(f.size[:2]) / 2 for f in fixtures for sign in (-1, 1)]
    if not xs:
        return 0.0, 0.0, 0.0, 0.0
    return min(xs) - 1.0, min(ys) - 1.0, max(xs) + 1.0, max(ys) + 1.0


def _wall_region(area: tuple[float, ...], draws: np.ndarray) -> Box:
    """A stretch of one of the room's four walls, 0.6-1.5 m wide, somewhere 0.3-1.6 m up."""
    x0, y0, x1, y1 = area
    lengths = np.array([x1 - x0, y1 - y0, x1 - x0, y1 - y0])
    wall = int(np.searchsorted(np.cumsum(lengths) / lengths.sum(), draws[0]))
    width = min(0.6 + 0.9 * draws[2], float(lengths[wall]))
    along = width / 2 + draws[1] * (lengths[wall] - width)
    bottom, height = 0.3 + 0.6 * draws[3], 0.3 + 0.5 * draws[4]
    z = bottom + height / 2
    centers = ((x0 + along, y0), (x1, y0 + along), (x1 - along, y1), (x0, y1 - along))
    across_x = wall % 2 == 0  # walls 0 and 2 run along x
    size = (width, SITE_DEPTH_M, height) if across_x else (SITE_DEPTH_M, width, height)
    return Box("site", "site", (*centers[wall], z), size)


def _floor_region(area: tuple[float, ...], draws: np.ndarray, band: bool) -> Box:
    """A rug (1.0-2.5 x 0.8-1.8 m on the floor), or a band of real surface 0.4-1.2 m up."""
    x0, y0, x1, y1 = area
    sx, sy = 1.0 + 1.5 * draws[2], 0.8 + 1.0 * draws[3]
    x = x0 + sx / 2 + draws[0] * max(x1 - x0 - sx, 0.0)
    y = y0 + sy / 2 + draws[1] * max(y1 - y0 - sy, 0.0)
    if band:
        return Box("site", "site", (x, y, 0.8), (sx, sy, 0.8))
    return Box("site", "site", (x, y, 0.0), (sx, sy, SITE_DEPTH_M))


def spurious_sites(
    room_size: Sequence[float],
    fixtures: Sequence[Box],
    occluders: Sequence[Box],
    per_m2: float,
    rng: np.random.Generator,
) -> list[SpuriousSite]:
    """The run's hallucination sites: Poisson(per_m2 x area) of them, drawn once before the
    first frame (a count, then six uniforms per site, whatever the site's kind)."""
    area = _site_area(room_size, fixtures)
    square_m = max(area[2] - area[0], 0.0) * max(area[3] - area[1], 0.0)
    recorded = not (room_size[0] > 0 and room_size[1] > 0)
    seats = [box for box in occluders if box.kind == "occluder" and box.label != "wall"]
    sites = []
    for index in range(int(rng.poisson(per_m2 * square_m))):
        draws = rng.random(6)
        kind, region, occluder = "floor", None, None
        if draws[5] < WALL_SHARE:
            kind = "band" if recorded else "wall"
        elif draws[5] >= WALL_SHARE + FLOOR_SHARE and seats:
            seat = seats[int(draws[0] * len(seats))]
            kind, occluder = ("tall" if seat.size[2] > TALL_OCCLUDER_M else "low"), seat.id
        if kind == "wall":
            region = _wall_region(area, draws)
        elif kind in ("floor", "band"):
            region = _floor_region(area, draws, kind == "band")
        labels = SITE_LABELS["wall" if kind == "band" else kind]
        first = int(draws[4] * len(labels)) % len(labels)
        pair = (labels[first], labels[(first + 1) % len(labels)])
        sites.append(SpuriousSite(index, kind, pair, region, occluder))
    return sites


def _image_window(region: Box, render: Render) -> tuple[slice, slice] | None:
    """Rows and columns of the image the region can show in (None: out of view).

    The box's edges are clipped to the plane in front of the camera first, so a rug the camera
    stands on projects to the part of the image it can fill, not to the whole image.
    """
    camera, pose = render.camera, render.pose
    half = np.divide(region.size, 2)
    signs = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    local = (np.array(region.center) + half * np.array(signs) - pose[:3, 3]) @ pose[:3, :3]
    near = camera.min_depth / 2
    points = [corner for corner in local if corner[2] > near]
    for i, j in itertools.combinations(range(8), 2):
        if sum(a != b for a, b in zip(signs[i], signs[j], strict=True)) != 1:
            continue  # not an edge of the box
        first, second = local[i], local[j]
        if (first[2] - near) * (second[2] - near) < 0:  # the edge crosses the plane
            along = (near - first[2]) / (second[2] - first[2])
            points.append(first + along * (second - first))
    if not points:
        return None
    front = np.array(points)
    cols = camera.fx * front[:, 0] / front[:, 2] + camera.cx
    rows = camera.fy * front[:, 1] / front[:, 2] + camera.cy
    left, right = max(int(cols.min()), 0), min(math.ceil(cols.max()) + 1, camera.width)
    top, bottom = max(int(rows.min()), 0), min(math.ceil(rows.max()) + 1, camera.height)
    if left >= right or top >= bottom:
        return None
    return slice(top, bottom), slice(left, right)


def _region_mask(region: Box, render: Render, background: np.ndarray) -> np.ndarray | None:
    """The background pixels whose surface point lies inside the region (None: none in view)."""
    window = _image_window(region, render)
    if window is None:
        return None
    rows, cols = window
    camera, pose = render.camera, render.pose
    low = np.subtract(region.center, np.divide(region.size, 2))
    high = np.add(region.center, np.divide(region.size, 2))
    ray_x = (np.arange(cols.start, cols.stop) - camera.cx) / camera.fx
    ray_y = (np.arange(rows.start, rows.stop) - camera.cy) / camera.fy
    depth = render.depth[rows, cols]
    inside = background[rows, cols].copy()
    for axis in (2, 0, 1):  # world z, x, y: each separable in rows and columns
        slope = pose[axis, 0] * ray_x[None, :] + pose[axis, 1] * ray_y[:, None] + pose[axis, 2]
        coordinate = depth * slope + pose[axis, 3]
        inside &= (coordinate >= low[axis]) & (coordinate <= high[axis])
        if not inside.any():
            return None
    mask = np.zeros_like(background)
    mask[rows, cols] = inside
    return mask


def spurious_masks(
    sites: Sequence[SpuriousSite], render: Render, world: World, min_pixels: int
) -> list[tuple[SpuriousSite, np.ndarray]]:
    """The masks of the sites in view (at least `min_pixels` of them visible), in site order.

    A region's mask is the background surface (no object, fixture or occluder) inside it; an
    occluder site's mask is the occluder's visible pixels.
    """
    if not sites:
        return []
    occluders = render.occluder_instance
    background = (render.instance < 0) & (render.fixture_instance < 0) & (render.depth > 0)
    if occluders is not None:
        background &= occluders < 0
    index_of = {box.id: index for index, box in enumerate(world.occluders)}
    found = []
    for site in sites:
        mask = None
        if site.region is not None:
            mask = _region_mask(site.region, render, background)
        elif site.occluder in index_of and occluders is not None:
            mask = occluders == index_of[site.occluder]
        if mask is not None and int(mask.sum()) >= min_pixels:
            found.append((site, mask))
    return found


def spurious_scores(
    site: SpuriousSite, rng: np.random.Generator, score_noise: float
) -> dict[str, float]:
    """A hallucination's class scores, best first: its class, its runner-up and two distractor
    levels, each with the view's noise (four draws)."""
    noise = rng.normal(0.0, score_noise, size=4)
    low, high = DISTRACTOR_SCORE_RANGE
    base = {
        site.labels[0]: SPURIOUS_TOP_SCORE,
        site.labels[1]: SPURIOUS_TOP_SCORE - SPURIOUS_RIVAL_GAP,
    }
    others = [label for label in ("table", "desk", "counter", "shelf") if label not in base]
    base.update({others[0]: high, others[1]: low})
    noisy = zip(base.items(), noise, strict=True)
    scores = {label: min(1.0, max(0.0, score + float(n))) for (label, score), n in noisy}
    return dict(sorted(scores.items(), key=lambda pair: -pair[1]))
