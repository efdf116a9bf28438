"""Analytic frames for core tests: a camera at the origin looking down +z at a wall."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from core.decide import decide
from core.events import Event, OccupancyEvidence
from core.evolve import fold
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import SceneState

INTRINSICS = Intrinsics(width=160, height=120, fx=130.0, fy=130.0, cx=79.5, cy=59.5)


def look_pose(yaw_deg: float = 0.0) -> np.ndarray:
    """Camera-to-world pose at the origin, rotated about the camera's y axis by yaw."""
    yaw = np.deg2rad(yaw_deg)
    pose = np.eye(4)
    pose[:3, :3] = [[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]]
    return pose


def wall(distance: float = 3.0) -> np.ndarray:
    """Depth of a flat wall facing the camera."""
    return np.full((INTRINSICS.height, INTRINSICS.width), distance, dtype=np.float32)


def paint_box(depth: np.ndarray, center: tuple[float, float, float], size: float) -> np.ndarray:
    """Draw the front face of an axis-aligned cube (camera frame) into depth; return its mask."""
    cx, cy, cz = center
    half = size / 2
    front = cz - half
    u0 = int(np.ceil(INTRINSICS.fx * (cx - half) / front + INTRINSICS.cx))
    u1 = int(np.floor(INTRINSICS.fx * (cx + half) / front + INTRINSICS.cx))
    v0 = int(np.ceil(INTRINSICS.fy * (cy - half) / front + INTRINSICS.cy))
    v1 = int(np.floor(INTRINSICS.fy * (cy + half) / front + INTRINSICS.cy))
    mask = np.zeros(depth.shape, dtype=bool)
    mask[max(v0, 0) : max(v1 + 1, 0), max(u0, 0) : max(u1 + 1, 0)] = True
    closer = mask & (depth > front)
    depth[closer] = front
    return closer


def detection(label: str, mask: np.ndarray, embedding: np.ndarray | None = None) -> Detection:
    """An object detection with an optional embedding."""
    return Detection(
        label=label, score=0.9, kind="object", mask=Mask.from_array(mask), embedding=embedding
    )


def frame(
    frame_id: str,
    depth: np.ndarray,
    detections: Iterable[Detection] = (),
    pose: np.ndarray | None = None,
    t: float = 0.0,
) -> Frame:
    """A frame of the test camera."""
    return Frame(
        frame_id=frame_id,
        timestamp=t,
        intrinsics=INTRINSICS,
        pose=look_pose() if pose is None else pose,
        depth=depth,
        detections=tuple(detections),
    )


def scene_batch(
    batch_id: str,
    objects: dict[str, tuple[tuple[float, float, float], float]],
    *,
    detect: set[str] | None = None,
    occluders: Iterable[tuple[tuple[float, float, float], float]] = (),
    pose: np.ndarray | None = None,
    embeddings: dict[str, np.ndarray] | None = None,
    t: float = 0.0,
) -> Batch:
    """One-frame batch of a wall with cubes; `detect` names the cubes that get a mask."""
    depth = wall()
    masks = {}
    for name, (center, size) in objects.items():
        masks[name] = paint_box(depth, center, size)
    for center, size in occluders:
        covered = paint_box(depth, center, size)
        for name in masks:
            masks[name] &= ~covered
    names = set(objects) if detect is None else detect
    labels = {name: name.split("_")[0] for name in objects}
    embeddings = embeddings or {}
    detections = [
        detection(labels[n], masks[n], embeddings.get(n)) for n in sorted(names) if masks[n].any()
    ]
    return Batch(batch_id, (frame(f"{batch_id}-f0", depth, detections, pose, t),))


def track_events(events: Iterable[Event]) -> list[Event]:
    """The events of a batch about tracks: its occupancy map evidence set aside (a camera
    turned about its y axis sees a floor and walls in the world's height band)."""
    return [e for e in events if not isinstance(e, OccupancyEvidence)]


def run_log(state: SceneState, batches: Iterable[Batch]) -> tuple[SceneState, list[Event]]:
    """Each batch decided and folded in turn: the state after them and every event, in order."""
    log: list[Event] = []
    for batch in batches:
        events = decide(state, batch)
        state = fold(state, events)
        log += events
    return state, log
