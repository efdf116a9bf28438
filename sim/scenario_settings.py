"""Run settings of a scenario file: camera trajectory and recorded background (the detector: `sim.detector_settings`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim.scenario_fields import (
    ScenarioError,
    Section,
    number,
    positive,
    sequence,
    text,
    vector,
)

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Waypoint:
    """A point of the camera path (z None = eye height) and what the camera looks at there."""

    at: tuple[float, float, float | None]
    look_at: Vec3
    pause: float = 0.0  # share of each lap the camera stands here, looking at look_at


@dataclass(frozen=True)
class TrajectorySpec:
    """`waypoints`: a closed polyline walked `loops` times; `orbit`: an ellipse around `center`.

    An orbit looks at `look_at[k % len(look_at)]` during block k of `look_blocks` equal blocks
    of frames per lap, and its eye rises and falls by `bob_amplitude` metres `bob_cycles` times
    per lap (a circle at constant height when both radii are equal and the amplitude is 0).
    """

    type: str
    loops: int = 1
    points: tuple[Waypoint, ...] = ()
    center: Vec2 = (0.0, 0.0)
    radii: Vec2 = (0.0, 0.0)  # along x and y
    look_at: tuple[Vec3, ...] = ()
    look_blocks: int = 1
    start_angle: float = 0.0
    bob_amplitude: float = 0.0
    bob_cycles: float = 0.0


def _waypoint(value: Any, where: str) -> Waypoint:
    """One entry of `trajectory.points`."""
    section = Section(value, where)
    at = section.get("at", lambda item, path: vector(item, path, len(item) if item else 2))
    if len(at) not in (2, 3):
        raise ScenarioError(f"{where}.at: expected [x, y] or [x, y, z]")
    look = section.get("look_at", lambda item, path: vector(item, path, 3))
    pause = section.get("pause", lambda item, path: number(item, path, 0.0, 0.9), 0.0)
    section.finish()
    return Waypoint((at[0], at[1], at[2] if len(at) == 3 else None), look, pause)


def _radii(value: Any, where: str) -> Vec2:
    """An orbit's `radius`: one number (a circle) or [along x, along y] (an ellipse)."""
    if isinstance(value, list | tuple):
        return vector(value, where, 2, positive_only=True)  # type: ignore[no-any-return]
    radius = positive(value, where)
    return (radius, radius)


def _look_targets(value: Any, where: str) -> tuple[Vec3, ...]:
    """An orbit's `look_at`: one [x, y, z] point, or a list of them visited in turn."""
    if isinstance(value, list) and value and isinstance(value[0], list | tuple):
        return tuple(sequence(value, where, lambda item, at: vector(item, at, 3)))
    return (vector(value, where, 3),)


def _bob(value: Any, where: str) -> tuple[float, float]:
    """The `bob` section of an orbit: amplitude [m] and cycles per lap of the eye height."""
    section = Section(value, where)
    amplitude = section.get("amplitude", lambda item, at: positive(item, at, zero=True))
    cycles = section.get("cycles", lambda item, at: positive(item, at, zero=True))
    section.finish()
    return amplitude, cycles


def parse_trajectory(value: Any, where: str) -> TrajectorySpec:
    """The `trajectory` section."""
    section = Section(value, where)
    kind = section.get("type", text)
    loops = int(section.get("loops", lambda item, at: positive(item, at, integer=True), 1))
    if kind == "waypoints":
        points = tuple(section.get("points", lambda item, at: sequence(item, at, _waypoint)))
        if len(points) < 2:
            raise ScenarioError(f"{where}.points: needs at least two waypoints")
        if sum(point.pause for point in points) > 0.9:
            raise ScenarioError(f"{where}.points: the pauses take more than 0.9 of a lap")
        spec = TrajectorySpec(kind, loops, points=points)
    elif kind == "orbit":
        targets = section.get("look_at", _look_targets)
        blocks = section.get(
            "look_blocks", lambda item, at: int(positive(item, at, integer=True)), len(targets)
        )
        bob_amplitude, bob_cycles = section.get("bob", _bob, (0.0, 0.0))
        spec = TrajectorySpec(
            kind,
            loops,
            center=section.get("center", lambda item, at: vector(item, at, 2)),
            radii=section.get("radius", _radii),
            look_at=targets,
            look_blocks=blocks,
            start_angle=section.get("start_angle", number, 0.0),
            bob_amplitude=bob_amplitude,
            bob_cycles=bob_cycles,
        )
    else:
        raise ScenarioError(f"{where}.type: {kind!r} is not one of waypoints, orbit")
    section.finish()
    return spec


@dataclass(frozen=True)
class BackgroundSpec:
    """A recorded RGB-D sequence whose real depth and poses replace the synthetic room."""

    type: str
    path: Path  # absolute
    frames: tuple[int, int, int]  # start, stop, step of the recorded frame numbers


def parse_background(value: Any, where: str, repo_root: Path) -> BackgroundSpec:
    """The `background` section; `path` is relative to the repository root."""
    section = Section(value, where)
    kind = section.get("type", text)
    if kind != "recorded":
        raise ScenarioError(f"{where}.type: {kind!r} is not 'recorded'")
    path = (repo_root / section.get("path", text)).resolve()
    frames = section.get("frames", lambda item, at: vector(item, at, 3))
    section.finish()
    start, stop, step = (int(item) for item in frames)
    if any(item != int(item) for item in frames) or start < 0 or step <= 0 or stop <= start:
        raise ScenarioError(
            f"{where}.frames: expected integers [start, stop, step], 0 <= start < stop, step > 0"
        )
    if not path.is_dir():
        raise ScenarioError(f"{where}.path: no folder {path}")
    return BackgroundSpec(kind, path, (start, stop, step))
