"""Run settings of a scenario file: camera trajectory and recorded background (the detector: `sim.detector_settings`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, Field, model_validator

from sim.scenario_fields import (
    CHECKED,
    Count,
    NonNegative,
    Number,
    Positive,
    PositiveInt,
    Vec2,
    Vec3,
    field_error,
)

# Recorded backgrounds name their data folder relative to the repository root (the folder
# holding `sim/`), so one spelling works whichever folder the scenario file sits in.
REPO_ROOT = Path(__file__).resolve().parent.parent


def _eye_height_by_default(value: Any) -> Any:
    """A waypoint's [x, y] stands at eye height (z None); [x, y, z] gives the height."""
    if isinstance(value, list) and len(value) == 2:
        return [*value, None]
    if isinstance(value, list) and len(value) != 3:
        raise ValueError(f"expected [x, y] or [x, y, z], got {value!r}")
    return value


@dataclass(frozen=True)
class Waypoint:
    """A point of the camera path (z None = eye height) and what the camera looks at there."""

    __pydantic_config__ = CHECKED
    at: Annotated[tuple[Number, Number, Number | None], BeforeValidator(_eye_height_by_default)]
    look_at: Vec3
    # Share of each lap the camera stands here, looking at look_at; at most 0.9, so it walks.
    pause: Annotated[Number, Field(ge=0.0, le=0.9)] = 0.0


@dataclass(frozen=True)
class Bob:
    """An orbit's eye rises and falls by `amplitude` metres `cycles` times per lap."""

    __pydantic_config__ = CHECKED
    amplitude: NonNegative
    cycles: NonNegative


def _circle(value: Any) -> Any:
    """An orbit's `radius`: one number (a circle) or [along x, along y] (an ellipse)."""
    return value if isinstance(value, list) else [value, value]


Radii = Annotated[tuple[Positive, Positive], BeforeValidator(_circle)]


def _targets(value: Any) -> Any:
    """An orbit's `look_at`: one [x, y, z] point, or a list of them visited in turn."""
    return value if isinstance(value, list) and value and isinstance(value[0], list) else [value]


# The fields of each trajectory type (the others are unknown to it) and those it requires.
_TYPE_FIELDS = {
    "waypoints": ({"type", "loops", "points"}, ("points",)),
    "orbit": (
        {"type", "loops", "center", "radius", "look_at", "look_blocks", "start_angle", "bob"},
        ("center", "radius", "look_at"),
    ),
}


@dataclass(frozen=True)
class TrajectorySpec:
    """`waypoints`: a closed polyline walked `loops` times; `orbit`: an ellipse around `center`.

    An orbit looks at `look_at[k % len(look_at)]` during block k of `look_blocks` equal blocks
    of frames per lap (by default one block per target), and its eye bobs (a circle at
    constant height when both radii are equal and there is no bob).
    """

    __pydantic_config__ = CHECKED
    type: Literal["waypoints", "orbit"]
    loops: PositiveInt = 1
    points: Annotated[tuple[Waypoint, ...], Field(min_length=2)] = ()
    center: Vec2 = (0.0, 0.0)
    radii: Annotated[Radii, Field(alias="radius")] = (0.0, 0.0)  # along x and y
    look_at: Annotated[tuple[Vec3, ...], BeforeValidator(_targets)] = ()
    look_blocks: PositiveInt = 1
    start_angle: Number = 0.0
    bob: Bob = field(default_factory=lambda: Bob(0.0, 0.0))

    @model_validator(mode="before")
    @classmethod
    def _fields_of_its_type(cls, data: Any) -> Any:
        if not isinstance(data, dict) or data.get("type") not in _TYPE_FIELDS:
            return data
        kind = data["type"]
        known, required = _TYPE_FIELDS[kind]
        others = set().union(*(fields for fields, _ in _TYPE_FIELDS.values())) - known
        for key in data:
            if key in others:
                listed = ", ".join(sorted(known))
                raise field_error(key, f"unknown field (known for {kind!r}: {listed})")
        for key in required:
            if key not in data:
                raise field_error(key, "required")
        if kind == "orbit" and "look_blocks" not in data:
            data = {**data, "look_blocks": len(_targets(data["look_at"]))}
        return data

    def __post_init__(self) -> None:
        if sum(point.pause for point in self.points) > 0.9:
            raise field_error("points", "the pauses take more than 0.9 of a lap")


def _recorded_folder(path: Path) -> Path:
    folder = (REPO_ROOT / path).resolve()
    if not folder.is_dir():
        raise ValueError(f"no folder {folder}")
    return folder


@dataclass(frozen=True)
class BackgroundSpec:
    """A recorded RGB-D sequence whose real depth and poses replace the synthetic room."""

    __pydantic_config__ = CHECKED
    type: Literal["recorded"]
    path: Annotated[Path, AfterValidator(_recorded_folder)]  # absolute; the file's is in the repo
    frames: tuple[Count, Count, PositiveInt]  # start, stop, step of the recorded frame numbers

    def __post_init__(self) -> None:
        if self.frames[1] <= self.frames[0]:
            raise field_error("frames", f"stop {self.frames[1]} must exceed start {self.frames[0]}")
