"""A scenario's world frame by frame: where every object is after the events so far."""

from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass

import numpy as np

from sim.scenario_spec import Scenario
from sim.truth import FrameTruth, ScheduledEvent, TruthFixture, TruthObject
from sim.world import Box, World, object_on


@dataclass(frozen=True)
class Placement:
    """Where an object rests (or rested, or will appear) and whether it is there."""

    present: bool
    support: str
    at: tuple[float, float]
    yaw: float


class Timeline:
    """Worlds and placements per frame; the world only changes at event frames, so it is cached."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.fixture_boxes = {spec.id: spec.box() for spec in scenario.fixtures}
        walls = tuple(wall.box(index) for index, wall in enumerate(scenario.walls))
        self.occluders = walls + tuple(spec.box() for spec in scenario.occluders)
        placements = {
            spec.id: Placement(not spec.absent, spec.on, spec.at, spec.yaw)
            for spec in scenario.objects
        }
        self.epoch_starts = [0]
        self.epoch_placements = [dict(placements)]
        scheduled = []
        for event in scenario.events:  # sorted by frame
            before = placements[event.object]
            after = Placement(
                event.type != "disappear",
                event.on or before.support,
                event.at if event.at is not None else before.at,
                event.yaw if event.yaw is not None else before.yaw,
            )
            placements[event.object] = after
            parent = None if event.type == "disappear" else after.support
            scheduled.append(ScheduledEvent(event.frame, event.type, event.object, parent))
            if event.frame == self.epoch_starts[-1]:
                self.epoch_placements[-1] = dict(placements)
            else:
                self.epoch_starts.append(event.frame)
                self.epoch_placements.append(dict(placements))
        self.events = tuple(scheduled)
        self.epoch_worlds = [self._world(state) for state in self.epoch_placements]

    def _epoch(self, frame_index: int) -> int:
        """Index of the epoch (stretch between events) holding this frame."""
        return bisect.bisect_right(self.epoch_starts, frame_index) - 1

    def placements(self, frame_index: int) -> dict[str, Placement]:
        """Every object's placement at this frame."""
        return self.epoch_placements[self._epoch(frame_index)]

    def world(self, frame_index: int) -> World:
        """The world as it is at this frame (present objects only, in scenario order, and the
        people walking through it at this frame)."""
        walkers = (person.box_at(frame_index) for person in self.scenario.people)
        people = tuple(box for box in walkers if box is not None)
        return self.epoch_worlds[self._epoch(frame_index)].with_people(people)

    def object_box(self, object_id: str, placement: Placement) -> Box:
        """The object's box for a placement."""
        spec = self.scenario.object(object_id)
        support = self.fixture_boxes[placement.support]
        return object_on(support, spec.id, spec.label, spec.size, placement.at, placement.yaw)

    def _world(self, placements: dict[str, Placement]) -> World:
        """World with the fixtures, occluders and the present objects."""
        objects = tuple(
            self.object_box(object_id, placement)
            for object_id, placement in placements.items()
            if placement.present
        )
        return World(
            room_size=self.scenario.room_size,
            fixtures=tuple(self.fixture_boxes.values()),
            objects=objects,
            occluders=self.occluders,
            include_room=self.scenario.background is None,
        )

    def world_with(self, frame_index: int, object_id: str) -> World:
        """The frame's world with one absent object put back where it was (counterfactuals)."""
        world = self.world(frame_index)
        placement = self.placements(frame_index)[object_id]
        box = self.object_box(object_id, dataclasses.replace(placement, present=True))
        return world.with_object(box)

    def truth(self, frame_index: int, instance: np.ndarray) -> FrameTruth:
        """Every object's truth at this frame; visible pixels come from the instance map."""
        world = self.world(frame_index)
        counts = np.bincount(instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
        visible = {box.id: int(counts[index]) for index, box in enumerate(world.objects)}
        objects = []
        for object_id, placement in self.placements(frame_index).items():
            box = self.object_box(object_id, placement)
            objects.append(
                TruthObject(
                    object_id=object_id,
                    label=box.label,
                    center=box.center,
                    present=placement.present,
                    # Absent objects rest on nothing; their center is where they were or will be.
                    parent=placement.support if placement.present else None,
                    visible_pixels=visible.get(object_id, 0),
                )
            )
        return FrameTruth(frame_index, tuple(objects))

    def fixture_truths(self) -> tuple[TruthFixture, ...]:
        """Each fixture's box center and size."""
        return tuple(
            TruthFixture(box.id, box.label, box.center, box.size)
            for box in self.fixture_boxes.values()
        )
