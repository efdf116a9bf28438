"""Camera paths of synthetic scenarios: closed waypoint polylines and orbits, as look-at poses."""

from __future__ import annotations

import math

import numpy as np

from sim.camera import look_at
from sim.scenario_settings import TrajectorySpec

PATH_SAMPLE_SPACING_M = 0.05  # path checks test points this far apart: thinner than any wall


def _waypoint_nodes(spec: TrajectorySpec, eye_height: float) -> tuple[np.ndarray, np.ndarray]:
    """Eye positions and gaze targets of the closed polyline (first point repeated at the end)."""
    eyes = np.array(
        [(p.at[0], p.at[1], eye_height if p.at[2] is None else p.at[2]) for p in spec.points]
    )
    targets = np.array([p.look_at for p in spec.points], dtype=np.float64)
    return np.vstack([eyes, eyes[:1]]), np.vstack([targets, targets[:1]])


def _along_polyline(
    eyes: np.ndarray, targets: np.ndarray, fraction: float, pauses: tuple[float, ...] = ()
) -> tuple[np.ndarray, np.ndarray]:
    """Eye and gaze target at `fraction` of a lap: pauses at the waypoints, constant speed between."""
    lengths = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    stops = np.zeros(len(lengths)) if not pauses else np.asarray(pauses, dtype=np.float64)
    # Each waypoint takes its pause share of the lap, then its segment a share of the rest
    # proportional to the segment's length.
    moving = (1.0 - stops.sum()) * lengths / max(float(lengths.sum()), 1e-12)
    starts = np.concatenate([[0.0], np.cumsum(stops + moving)])
    segment = min(int(np.searchsorted(starts, fraction, side="right")) - 1, len(lengths) - 1)
    into = fraction - starts[segment] - stops[segment]
    local = 0.0 if into <= 0 or moving[segment] == 0 else min(into / moving[segment], 1.0)
    # The gaze target slides between the two waypoints' targets, so views turn smoothly.
    eye = eyes[segment] + local * (eyes[segment + 1] - eyes[segment])
    target = targets[segment] + local * (targets[segment + 1] - targets[segment])
    return eye, target


def _orbit_eye(spec: TrajectorySpec, eye_height: float, angle: float) -> np.ndarray:
    """Eye position on the orbit ellipse, raised or lowered by its bob."""
    height = eye_height
    if spec.bob.amplitude > 0:
        height += spec.bob.amplitude * math.sin(spec.bob.cycles * angle)
    return np.array(
        [
            spec.center[0] + spec.radii[0] * math.cos(angle),
            spec.center[1] + spec.radii[1] * math.sin(angle),
            height,
        ]
    )


def _orbit_target(spec: TrajectorySpec, frame_index: int, frames: int) -> np.ndarray:
    """The gaze target of a frame: a lap's equal blocks of frames visit the targets in turn."""
    # Integer arithmetic, so a block boundary never shifts by a frame through rounding.
    block = frame_index * spec.loops * spec.look_blocks // frames % spec.look_blocks
    return np.asarray(spec.look_at[block % len(spec.look_at)], dtype=np.float64)


def trajectory_poses(spec: TrajectorySpec, frames: int, eye_height: float) -> list[np.ndarray]:
    """Camera-to-world poses, `spec.loops` laps spread evenly over `frames` frames."""
    poses = []
    if spec.type == "waypoints":
        eyes, targets = _waypoint_nodes(spec, eye_height)
        pauses = tuple(point.pause for point in spec.points)
    for frame_index in range(frames):
        lap_fraction = (frame_index * spec.loops / frames) % 1.0
        if spec.type == "waypoints":
            eye, target = _along_polyline(eyes, targets, lap_fraction, pauses)
        else:
            angle = spec.start_angle + 2.0 * math.pi * lap_fraction
            eye = _orbit_eye(spec, eye_height, angle)
            target = _orbit_target(spec, frame_index, frames)
        poses.append(look_at(eye, target))
    return poses


def path_samples(spec: TrajectorySpec, eye_height: float) -> list[tuple[str, np.ndarray]]:
    """Points along one lap, each with a name of the path piece it lies on (for errors)."""
    samples: list[tuple[str, np.ndarray]] = []
    if spec.type == "waypoints":
        eyes, _ = _waypoint_nodes(spec, eye_height)
        count = len(spec.points)
        for index in range(count):
            start, end = eyes[index], eyes[index + 1]
            steps = max(int(np.linalg.norm(end - start) / PATH_SAMPLE_SPACING_M), 1)
            name = f"the segment from points[{index}] to points[{(index + 1) % count}]"
            samples.extend((name, start + (end - start) * k / steps) for k in range(steps + 1))
    else:
        steps = max(int(2.0 * math.pi * max(spec.radii) / PATH_SAMPLE_SPACING_M), 8)
        samples.extend(
            ("the orbit", _orbit_eye(spec, eye_height, 2.0 * math.pi * k / steps))
            for k in range(steps)
        )
    return samples
