"""500 real frames of a static kitchen: no published track is ever demoted or removed.

The frames, poses and depth are the real 7-Scenes kitchen's (Kinect v1 noise, holes, real pose
drift). The objects are ours: the real surfaces inside five fixed 20 cm boxes placed on points
the first frame sees, each frame's mask the pixels whose depth lands inside a box. The detector
is realistic in what matters here: it misses 15% of the masks at random, never reports one under
150 pixels, and never one whose box the image border cuts to less than half. So besides the
random misses, the misses happen where only a sliver of a box is in view (the border, far away,
grazing) - exactly where a memory must not conclude that something is gone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from core.decide import decide
from core.events import TrackDemoted, TrackRemoved
from core.evolve import fold
from core.geometry import backproject_pixels, camera_to_world, project, world_to_camera
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import SceneState

FRAMES = 500
INTRINSICS = Intrinsics(width=640, height=480, fx=585.0, fy=585.0, cx=320.0, cy=240.0)
# Pixels of the first frame whose surfaces become the objects, and their labels.
ANCHORS = {
    "mug": (300, 250),
    "bowl": (380, 300),
    "book": (220, 330),
    "remote": (460, 220),
    "box": (320, 160),
}
HALF = 0.10  # metres: each object is the real geometry inside a 20 cm cube
MISS_RATE, MIN_MASK_PIXELS = 0.15, 150


def load(path: Path, index: int) -> tuple[np.ndarray, np.ndarray]:
    depth = np.asarray(Image.open(path / f"frame-{index:06d}.depth.png"), dtype=np.float64) / 1000
    pose = np.loadtxt(path / f"frame-{index:06d}.pose.txt")
    return depth.astype(np.float32), pose


def box_mask(depth: np.ndarray, pose: np.ndarray, center: np.ndarray) -> np.ndarray:
    """What a detector reports of the cube around `center`: the pixels whose depth lands inside
    it, or nothing when the cube is cut to less than half by the image border (detectors rarely
    report a truncated object)."""
    corners = center + HALF * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)
    camera = world_to_camera(corners, pose)
    if (camera[:, 2] <= 0.1).any():
        return np.zeros(0, dtype=np.intp)
    u, v = project(camera, INTRINSICS)
    u0, u1 = max(int(u.min()), 0), min(int(u.max()) + 1, INTRINSICS.width)
    v0, v1 = max(int(v.min()), 0), min(int(v.max()) + 1, INTRINSICS.height)
    full = (u.max() - u.min() + 1) * (v.max() - v.min() + 1)
    if u0 >= u1 or v0 >= v1 or (u1 - u0) * (v1 - v0) < 0.5 * full:
        return np.zeros(0, dtype=np.intp)
    rows, cols = np.mgrid[v0:v1, u0:u1]
    flat = (rows * INTRINSICS.width + cols).reshape(-1)
    flat = flat[depth.reshape(-1)[flat] > 0]
    points = camera_to_world(
        backproject_pixels(flat, depth.reshape(-1)[flat].astype(np.float64), INTRINSICS), pose
    )
    inside: np.ndarray = flat[(np.abs(points - center) <= HALF).all(axis=1)]
    return inside


def test_a_static_real_kitchen_keeps_every_published_track(real_kitchen: Path) -> None:
    depth, pose = load(real_kitchen, 0)
    centers = {}
    for label, (u, v) in ANCHORS.items():
        flat = np.array([v * INTRINSICS.width + u])
        centers[label] = camera_to_world(
            backproject_pixels(flat, depth.reshape(-1)[flat].astype(np.float64), INTRINSICS), pose
        )[0]
    rng = np.random.default_rng(7)
    state = SceneState()
    published: set[str] = set()
    lost: list[str] = []
    reported = 0
    for index in range(FRAMES):
        depth, pose = load(real_kitchen, index)
        detections = []
        for label, center in centers.items():
            inside = box_mask(depth, pose, center)
            if inside.size < MIN_MASK_PIXELS or rng.random() < MISS_RATE:
                continue
            mask = np.zeros(depth.shape, dtype=bool)
            mask.reshape(-1)[inside] = True
            detections.append(Detection(label, 0.9, "object", Mask.from_array(mask)))
        reported += len(detections)
        frame = Frame(f"f{index:06d}", index / 30.0, INTRINSICS, pose, depth, tuple(detections))
        events = decide(state, Batch(f"b{index:06d}", (frame,)))
        lost += [
            f"{e.type} {e.track_id} at frame {index}"
            for e in events
            if isinstance(e, TrackDemoted | TrackRemoved) and e.track_id in published
        ]
        state = fold(state, events)
        published |= {t.track_id for t in state.tracks.values() if t.lifecycle == "confirmed"}
    assert reported > FRAMES  # the boxes were seen, over and over
    assert len(published) >= len(ANCHORS)
    assert lost == []
