"""Scenario files: a YAML description of a room, its furniture, objects, camera walk and events."""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import AfterValidator, TypeAdapter

from sim.detector_settings import DetectorSpec, PhantomSpec
from sim.people import PersonSpec, check_people
from sim.scenario_checks import check_events, check_layout, check_trajectory
from sim.scenario_fields import (
    CHECKED,
    Count,
    Positive,
    PositiveInt,
    ScenarioError,
    Size3,
    Text,
    Vec3,
    validated,
)
from sim.scenario_parts import (
    CameraSpec,
    EventEntry,
    EventSpec,
    FixtureSpec,
    ObjectSpec,
    OccluderSpec,
    WallSpec,
)
from sim.scenario_settings import REPO_ROOT, BackgroundSpec, TrajectorySpec
from sim.scenario_spec import Scenario

__all__ = [
    "REPO_ROOT",
    "BackgroundSpec",
    "CameraSpec",
    "DetectorSpec",
    "EventSpec",
    "FixtureSpec",
    "ObjectSpec",
    "OccluderSpec",
    "PersonSpec",
    "PhantomSpec",
    "Scenario",
    "ScenarioError",
    "TrajectorySpec",
    "WallSpec",
    "load_scenario",
    "scenario_from_dict",
]

# Event recall counts a change recalled when the memory reflects it within this many batches of
# its first observable batch: 10 batches of two frames at 10 Hz is two seconds.
DEFAULT_EVENT_LATENCY_BATCHES = 10
NAME_PATTERN = re.compile(r"^[A-Za-z0-9._-]+$")  # names end up inside wire batch ids


def _batch_id_safe(name: str) -> str:
    if not NAME_PATTERN.match(name):
        raise ValueError(
            f"must be a non-empty string of letters, digits, '.', '_', '-', got {name!r}"
        )
    return name


@dataclass(frozen=True)
class Room:
    """The synthetic room: its x and y extents and its height [m]."""

    __pydantic_config__ = CHECKED
    size: Size3


@dataclass(frozen=True)
class Evaluation:
    """How the evaluation judges this world."""

    __pydantic_config__ = CHECKED
    event_latency_batches: PositiveInt = DEFAULT_EVENT_LATENCY_BATCHES


@dataclass(frozen=True)
class ScenarioFile:
    """A scenario file as written; `scenario_from_dict` checks its parts against each other."""

    __pydantic_config__ = CHECKED
    name: Annotated[Text, AfterValidator(_batch_id_safe)]
    seed: Count
    camera: CameraSpec
    fixtures: tuple[FixtureSpec, ...]
    frames: PositiveInt | None = None  # required, unless a recorded background selects them
    frame_period: Positive = 0.1  # [s]
    room: Room | None = None  # required, unless a recorded background replaces it
    walls: tuple[WallSpec, ...] = ()
    occluders: tuple[OccluderSpec, ...] = ()
    objects: tuple[ObjectSpec, ...] = ()
    events: tuple[EventEntry, ...] = ()
    trajectory: TrajectorySpec | None = None  # required without a recorded background
    background: BackgroundSpec | None = None
    detector: DetectorSpec = field(default_factory=DetectorSpec)
    people: tuple[PersonSpec, ...] = ()
    evaluation: Evaluation = field(default_factory=Evaluation)


_FILE = TypeAdapter(ScenarioFile)
# Where `null` means None, not "the default": no fixture segmenter, no appearance vector.
_NULL_MEANS_NONE = {("detector", "fixtures"), ("detector", "appearance", "dim")}


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and reads only true/false as booleans."""


# YAML 1.1 reads a bare `on` (our support field) as the boolean true; keep YAML 1.2 booleans.
_UniqueKeyLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool",
    re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
    list("tTfF"),
)


def _construct_unique_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    """Build a mapping, failing on a repeated key with its line number."""
    keys: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        if key in keys:
            line = key_node.start_mark.line + 1
            raise ScenarioError(f"line {line}: duplicate key {key!r}")
        keys.add(key)
    return loader.construct_mapping(node)


_UniqueKeyLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_unique_mapping
)


def _merge(base: dict[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """`base` with `overrides` merged in: mappings merge, None deletes, anything else replaces."""
    merged = copy.deepcopy(base)
    for key, value in overrides.items():
        if value is None:
            merged.pop(key, None)
        elif isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = _merge(dict(merged[key]), value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def load_scenario(
    path: str | Path, overrides: Mapping[str, Any] | None = None, *, frames: int | None = None
) -> Scenario:
    """Read, merge `overrides` into, optionally shorten to `frames`, and validate a scenario file.

    `frames` (or an override {"frames": n}) keeps the story: event frames scale by n / the
    file's frames, so a 20-frame test run still sees every event (the laps squeeze the same
    way); with a recorded background it keeps the first n selected frames.
    """
    path = Path(path)
    try:
        raw = yaml.load(path.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)
    except yaml.YAMLError as error:
        raise ScenarioError(f"{path}: not valid YAML: {error}") from error
    except ScenarioError as error:
        raise ScenarioError(f"{path}: {error}") from error
    if not isinstance(raw, dict):
        raise ScenarioError(f"{path}: the file must hold a mapping of scenario fields")
    overrides = dict(overrides or {})
    # A frames override means "the same story, shorter (or longer)": events scale with it.
    frames = overrides.pop("frames", None) if frames is None else frames
    merged = _merge(raw, overrides)
    if frames is not None:
        merged = _shortened(merged, frames)
    return scenario_from_dict(merged, source=path)


def _shortened(raw: dict[str, Any], frames: int) -> dict[str, Any]:
    """The scenario squeezed into `frames` frames, events keeping their relative times."""
    shortened = copy.deepcopy(raw)
    background = shortened.get("background")
    original: int | None  # the frame count before shortening
    if isinstance(background, dict):
        # A recording is shortened by keeping its first `frames` selected frames.
        try:
            start, stop, step = (int(value) for value in background["frames"])
            original = len(range(start, stop, step))
        except (KeyError, TypeError, ValueError) as error:
            raise ScenarioError(
                "background.frames: shortening needs [start, stop, step]"
            ) from error
        background["frames"] = [start, start + min(frames, original) * step, step]
        shortened.pop("frames", None)
    else:
        original = raw.get("frames")
        if not isinstance(original, int) or isinstance(original, bool) or original < 1:
            raise ScenarioError("frames: shortening needs the file's own positive integer frames")
        shortened["frames"] = frames
    timed = list(shortened.get("events") or [])
    for person in shortened.get("people") or []:
        if isinstance(person, dict):
            timed += person.get("keyframes") or []
    for entry in timed:
        if isinstance(entry, dict) and isinstance(entry.get("frame"), int):
            entry["frame"] = entry["frame"] * frames // original
    return shortened


def scenario_from_dict(raw: Mapping[str, Any], source: Path | None = None) -> Scenario:
    """Validate an already-parsed scenario mapping."""
    file = validated(_FILE, raw, _NULL_MEANS_NONE)
    room_size = file.room.size if file.room else None
    frames, trajectory, background = file.frames, file.trajectory, file.background
    if room_size is None and background is None:
        raise ScenarioError("room: required (only a recorded background may leave it out)")
    if background is not None:
        selected = len(range(*background.frames))
        if frames is not None and frames != selected:
            raise ScenarioError(
                f"frames: {frames} does not match the {selected} frames background.frames selects"
            )
        frames, trajectory = selected, None
    else:
        if frames is None:
            raise ScenarioError("frames: required")
        if trajectory is None:
            raise ScenarioError("trajectory: required without a recorded background")

    walls, fixtures, occluders, listed = file.walls, file.fixtures, file.occluders, file.objects
    detector, people = file.detector, file.people
    events_and_new = [(entry.spec(), entry.defined()) for entry in file.events]
    listed_ids = {spec.id for spec in listed}
    for index, (event, defined) in enumerate(events_and_new):
        if defined is not None and defined.id in listed_ids:
            raise ScenarioError(
                f"events[{index}].label: object {event.object!r} is already defined in objects"
            )
    file_order = tuple(event for event, _ in events_and_new)
    event_only = tuple(defined for _, defined in events_and_new if defined is not None)
    objects = listed + event_only
    check_layout(room_size, walls, fixtures, occluders, objects, len(listed))
    check_events(file_order, objects, fixtures, frames)
    taken = {spec.id for specs in (fixtures, occluders, objects) for spec in specs}
    check_people(people, room_size, frames, taken)
    check_phantoms(detector.phantoms, room_size)
    fixture_ids = {spec.id for spec in fixtures}
    object_ids = {spec.id for spec in objects}
    for index, group in enumerate(detector.appearance.look_alike):
        for object_id in group:
            if object_id not in object_ids:
                raise ScenarioError(
                    f"detector.appearance.look_alike[{index}]: unknown object {object_id!r}"
                )
    for fixture_id in (detector.fixtures.ambiguity or {}) if detector.fixtures else {}:
        if fixture_id not in fixture_ids:
            raise ScenarioError(f"detector.fixtures.ambiguity.{fixture_id}: unknown fixture")
    # A stable sort keeps same-frame events in file order.
    events = tuple(sorted(file_order, key=lambda event: event.frame))
    scenario = Scenario(
        name=file.name,
        seed=file.seed,
        frames=frames,
        camera=file.camera,
        room_size=room_size or (0.0, 0.0, 0.0),
        walls=walls,
        fixtures=fixtures,
        occluders=occluders,
        objects=objects,
        trajectory=trajectory,
        events=events,
        detector=detector,
        background=background,
        frame_period=file.frame_period,
        people=people,
        event_latency_batches=file.evaluation.event_latency_batches,
        source=source,
        raw=copy.deepcopy(dict(raw)),
    )
    if trajectory is not None:
        check_trajectory(scenario)
    return scenario


def check_phantoms(phantoms: tuple[PhantomSpec, ...], room_size: Vec3 | None) -> None:
    """Phantom pictures hang inside the room (a recorded background has no room to check)."""
    if room_size is None:
        return
    for index, phantom in enumerate(phantoms):
        if not all(0.0 <= phantom.at[axis] <= room_size[axis] for axis in range(3)):
            raise ScenarioError(
                f"detector.phantoms[{index}].at: {list(phantom.at)} is outside the room"
            )
