"""Run settings of a scenario file: camera trajectory, detector model and recorded background."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim.scenario_fields import (
    ScenarioError,
    Section,
    count,
    fraction,
    number,
    positive,
    sequence,
    text,
    vector,
)

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
DEPTH_NOISE_MODELS = ("kinect", "none")


@dataclass(frozen=True)
class Waypoint:
    """A point of the camera path (z None = eye height) and what the camera looks at there."""

    at: tuple[float, float, float | None]
    look_at: Vec3


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
    section.finish()
    return Waypoint((at[0], at[1], at[2] if len(at) == 3 else None), look)


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
class FixtureDetectorSpec:
    """Settings of the fixture segmenter (see `sim.detector.detect_fixtures`)."""

    recall: float = 1.0
    score_noise: float = 0.02
    min_visible_pixels: int = 400
    ambiguity: Mapping[str, Mapping[str, float]] | None = None


@dataclass(frozen=True)
class DetectorSpec:
    """The simulated object detector's degradations and the depth noise model."""

    recall: float = 1.0
    min_visible_pixels: int = 150
    false_positives_per_frame: float = 0.0
    label_confusion: float = 0.0
    mask_boundary_leak_px: int = 0
    depth_noise: str = "kinect"
    embedding_dim: int | None = 64
    embedding_noise: float = 0.0
    score: float = 0.9
    fixtures: FixtureDetectorSpec | None = FixtureDetectorSpec()


def _ambiguity(value: Any, where: str) -> dict[str, dict[str, float]]:
    """Fixture id -> {label: score} overrides."""
    section = Section(value, where)
    parsed = {}
    for fixture_id in map(str, value):
        scores = section.get(fixture_id, lambda item, at: Section(item, at).data)
        parsed[fixture_id] = {
            str(label): fraction(score, f"{where}.{fixture_id}.{label}")
            for label, score in scores.items()
        }
    return parsed


def _fixture_detector(value: Any, where: str) -> FixtureDetectorSpec:
    """The `detector.fixtures` section."""
    section, default = Section(value, where), FixtureDetectorSpec()
    spec = FixtureDetectorSpec(
        recall=section.get("recall", fraction, default.recall),
        score_noise=section.get(
            "score_noise", lambda item, at: positive(item, at, zero=True), 0.02
        ),
        min_visible_pixels=section.get("min_visible_pixels", count, default.min_visible_pixels),
        ambiguity=section.get("ambiguity", _ambiguity, None),
    )
    section.finish()
    return spec


def _embedding(value: Any, where: str) -> tuple[int | None, float]:
    """The `detector.embedding` section: dim (null = no embeddings) and noise sigma."""
    section = Section(value, where)
    dim = section.get("dim", lambda item, at: int(positive(item, at, integer=True)), None)
    noise = section.get("noise", lambda item, at: positive(item, at, zero=True), 0.0)
    section.finish()
    return dim, noise


def parse_detector(value: Any, where: str) -> DetectorSpec:
    """The `detector` section (every field optional)."""
    section, default = Section(value, where), DetectorSpec()
    noise_model = section.get("depth_noise", text, default.depth_noise)
    if noise_model not in DEPTH_NOISE_MODELS:
        raise ScenarioError(f"{where}.depth_noise: {noise_model!r} is not one of kinect, none")
    dim, embedding_noise = section.get("embedding", _embedding, (64, 0.0))
    fixtures_given = section.data.get("fixtures", {}) is not None  # explicit null turns them off
    fixtures = section.get("fixtures", _fixture_detector, FixtureDetectorSpec())
    spec = DetectorSpec(
        recall=section.get("recall", fraction, default.recall),
        min_visible_pixels=section.get("min_visible_pixels", count, default.min_visible_pixels),
        false_positives_per_frame=section.get(
            "false_positives_per_frame", lambda item, at: positive(item, at, zero=True), 0.0
        ),
        label_confusion=section.get("label_confusion", fraction, 0.0),
        mask_boundary_leak_px=section.get("mask_boundary_leak_px", count, 0),
        depth_noise=noise_model,
        embedding_dim=dim,
        embedding_noise=embedding_noise,
        score=section.get("score", fraction, default.score),
        fixtures=fixtures if fixtures_given else None,
    )
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
