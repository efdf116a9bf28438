"""The validated scenario: every part and run setting of one scenario file, and its hash.

Kept apart from the loader (`sim.scenario`) so the consistency checks can take a whole scenario
without importing the module that calls them.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sim.detector_settings import DetectorSpec
from sim.people import PersonSpec
from sim.scenario_parts import (
    CameraSpec,
    EventSpec,
    FixtureSpec,
    ObjectSpec,
    OccluderSpec,
    WallSpec,
)
from sim.scenario_settings import BackgroundSpec, TrajectorySpec


@dataclass(frozen=True)
class Scenario:
    """A validated scenario; `raw` keeps the effective YAML mapping for hashing and caching."""

    name: str
    seed: int
    frames: int
    camera: CameraSpec
    room_size: tuple[float, float, float]
    walls: tuple[WallSpec, ...]
    fixtures: tuple[FixtureSpec, ...]
    occluders: tuple[OccluderSpec, ...]
    objects: tuple[ObjectSpec, ...]  # every object, including those only an appear event adds
    trajectory: TrajectorySpec | None  # None when a recorded background supplies the poses
    events: tuple[EventSpec, ...]  # sorted by frame
    detector: DetectorSpec
    background: BackgroundSpec | None
    frame_period: float
    people: tuple[PersonSpec, ...] = ()
    event_latency_batches: int = 10  # the evaluation's bound on event latency
    source: Path | None = field(default=None, compare=False)
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def sha256(self) -> str:
        """Hash of the effective scenario (overrides included), as canonical JSON."""
        canonical = json.dumps(self.raw, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canonical.encode("utf-8")).hexdigest()

    def fixture(self, fixture_id: str) -> FixtureSpec:
        """The fixture with this id."""
        for spec in self.fixtures:
            if spec.id == fixture_id:
                return spec
        raise KeyError(f"no fixture {fixture_id!r} in scenario {self.name!r}")

    def object(self, object_id: str) -> ObjectSpec:
        """The object with this id."""
        for spec in self.objects:
            if spec.id == object_id:
                return spec
        raise KeyError(f"no object {object_id!r} in scenario {self.name!r}")

    @property
    def object_labels(self) -> tuple[str, ...]:
        """Distinct object labels, in first-seen order (label confusion and false positives)."""
        return tuple(dict.fromkeys(spec.label for spec in self.objects))
