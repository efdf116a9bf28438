"""A whole generated world: house, objects, route, people and events, as a scenario mapping."""

from __future__ import annotations

import functools
import itertools
import math
import random
from typing import Any

from pbdag_errors import Refused
from sim.generator.events import EventEntry, Scripter, Unscriptable
from sim.generator.knobs import WorldKnobs, WorldNotes, active_knobs
from sim.generator.layout import WALL_HEIGHT, House, Item, Piece, build_house
from sim.generator.objects import ON, TALL_ON, Shelver
from sim.generator.route import (
    Planner,
    Route,
    build_route,
    standing_spot,
    visit_frames,
    visit_order,
    walker,
)
from sim.generator.scripting import destinations, scripted_events
from sim.generator.visibility import Sightings, hidden_fraction, sightings
from sim.scenario import ScenarioError, scenario_from_dict

MAX_ATTEMPTS = 30
CAMERA = {
    "width": 640,
    "height": 480,
    "fx": 525,
    "fy": 525,
    "cx": 319.5,
    "cy": 239.5,
    "eye_height": 1.3,
    "min_depth": 0.3,
    "max_depth": 6.0,
}
DETECTOR = {"labels": {"confusable": [["cup", "mug"], ["desk", "table"]]}}
SMALL_BEHIND = ("mug", "cup")  # narrower than every cover
FRAMES_PER_VISIT = 11  # a dynamic world's route stops about once per this many frames
PAUSE_SHARE = 0.5  # share of the lap the robot stands at its viewpoints


class GenerationError(Refused, RuntimeError):
    """No deterministic resample of this seed gave a world that passes every check."""


class _Resample(Refused):
    """This draw does not work out; try the next one."""


def _r(value: float) -> float:
    return round(float(value), 3)


def _items(
    rng: random.Random,
    house: House,
    shelver: Shelver,
    knobs: WorldKnobs,
    planner_views: dict[str, list[tuple[float, float]]],
    active: bool,
) -> None:
    """Objects on every fixture: a class on two fixtures, small things behind taller ones."""
    fixtures = house.fixtures()
    pair_label = rng.choice(("mug", "book", "cup"))
    hosts = [piece for piece in fixtures if pair_label in ON[piece.label]]
    rng.shuffle(hosts)
    for piece in hosts[:2]:
        shelver.place(piece.id, pair_label)
    if not active:
        coverable = [p for p in fixtures if TALL_ON[p.label] and p.id in planner_views]
        rng.shuffle(coverable)
        for piece in coverable[:3]:
            small = rng.choice(
                [label for label in SMALL_BEHIND if label in ON[piece.label]] or ["mug"]
            )
            shelver.place_behind(
                piece.id, small, rng.choice(TALL_ON[piece.label]), planner_views[piece.id][0]
            )
    if knobs.objects is not None:
        wanted = rng.randint(*knobs.objects)
        order = list(fixtures)
        rng.shuffle(order)
        tries = 0
        while len(house.items) < wanted and tries < 10 * wanted:
            piece = order[tries % len(order)]
            shelver.place(piece.id, rng.choice(ON[piece.label]))
            tries += 1
        if len(house.items) != wanted:
            raise _Resample("objects do not fit")
        return
    for piece in fixtures:
        for _ in range(rng.randint(*knobs.clutter)):
            shelver.place(piece.id, rng.choice(ON[piece.label]))


def _step_cost(house: House, here: Piece, piece_id: str) -> float:
    """Distance to the next fixture, a room change counting 3 m extra."""
    there = house.piece(piece_id)
    return math.dist(here.center, there.center) + (3.0 if there.room != here.room else 0.0)


def _tour(rng: random.Random, house: House) -> list[str]:
    """Fixtures in a walking order: nearest next, a room change counting 3 m extra."""
    left = [piece.id for piece in house.fixtures()]
    rng.shuffle(left)
    tour = [left.pop()]
    while left:
        here = house.piece(tour[-1])
        left.sort(key=functools.partial(_step_cost, house, here))
        tour.append(left.pop(0))
    return tour


def _route_entry(route: Route) -> dict[str, Any]:
    points = []
    for at, look, pause in zip(route.points, route.look_at, route.pause, strict=True):
        point: dict[str, Any] = {"at": [_r(at[0]), _r(at[1])], "look_at": [_r(v) for v in look]}
        if pause > 0:
            point["pause"] = round(pause, 4)
        points.append(point)
    return {"type": "waypoints", "loops": 1, "points": points}


def _floor_box(piece: Piece) -> dict[str, Any]:
    """A fixture's or an occluder's entry of the scenario file."""
    return {
        "id": piece.id,
        "label": piece.label,
        "center": [_r(piece.center[0]), _r(piece.center[1])],
        "size": [_r(v) for v in piece.size],
    }


def _mapping(
    name: str,
    seed: int,
    house: House,
    frames: int,
    frame_period: float,
    items: list[Item],
    route: Route,
    people: list[dict[str, Any]],
    events: list[EventEntry],
) -> dict[str, Any]:
    walls = [
        {"from": [_r(a[0]), _r(a[1])], "to": [_r(b[0]), _r(b[1])], "height": WALL_HEIGHT}
        for wall in house.walls
        for a, b in wall.segments()
    ]
    fixtures = [_floor_box(p) for p in house.pieces if p.fixture]
    occluders = [_floor_box(p) for p in house.pieces if not p.fixture]
    objects = [
        {
            "id": i.id,
            "label": i.label,
            "size": [_r(v) for v in i.size],
            "on": i.on,
            "at": [_r(i.at[0]), _r(i.at[1])],
        }
        for i in items
    ]
    mapping: dict[str, Any] = {
        "name": name,
        "seed": seed,
        "frames": frames,
        "frame_period": frame_period,
        "camera": dict(CAMERA),
        "room": {"size": [_r(house.size[0]), _r(house.size[1]), WALL_HEIGHT]},
        "walls": walls,
        "fixtures": fixtures,
    }
    if occluders:
        mapping["occluders"] = occluders
    mapping["objects"] = objects
    mapping["trajectory"] = _route_entry(route)
    if people:
        mapping["people"] = people
    if events:
        mapping["events"] = sorted(events, key=lambda e: int(str(e["frame"])))
    mapping["detector"] = {
        "labels": {"confusable": [list(g) for g in DETECTOR["labels"]["confusable"]]}
    }
    return mapping


def _people(
    rng: random.Random,
    planner: Planner,
    house: House,
    route: Route,
    spans: list[tuple[int, int]],
    count: int,
    frames: int,
) -> list[dict[str, Any]]:
    """People who walk in and stand between the robot and the fixture of one of its visits."""
    people: list[dict[str, Any]] = []
    choices = list(range(1, len(route.visits)))
    rng.shuffle(choices)
    busy: list[tuple[int, int]] = []
    for index in choices:
        if len(people) >= count:
            break
        visit = route.visits[index]
        first, last = spans[index]
        leave = min(last + rng.randint(4, 14), frames - 1)
        if any(first <= b + 10 and a <= leave + 10 for a, b in busy):
            continue
        spot = standing_spot(planner, visit, house.piece(visit.fixture))
        if spot is None:
            continue
        others = [v.at for v in route.visits if math.dist(v.at, spot) > 2.5]
        if not others:
            continue
        start = rng.choice(others)
        keys = walker(planner, start, spot, max(first - 1, 0), leave, frames)
        if keys is None:
            continue
        busy.append((first, leave))
        person: dict[str, Any] = {
            "id": f"person_{len(people) + 1}",
            "keyframes": [{"frame": f, "at": [_r(x), _r(y)]} for f, (x, y) in keys],
        }
        if rng.random() < 0.5:
            person["detected_as"] = "person"
        people.append(person)
    return people


def _active_world(
    rng: random.Random,
    name: str,
    seed: int,
    attempt: int,
    knobs: WorldKnobs,
    house: House,
    planner: Planner,
    views: dict[str, list[tuple[float, float]]],
) -> tuple[dict[str, Any], WorldNotes]:
    """An active world: the house and its objects, with a short passive walk between two
    fixtures of one room (the rollout starts from its first point)."""
    first = rng.choice(house.fixtures())
    same_room = [p for p in house.fixtures() if p.room == first.room and p.id != first.id]
    second = rng.choice(same_room or [p for p in house.fixtures() if p.id != first.id])
    route = build_route(rng, planner, views, [first.id, second.id], 0.0)
    mapping = _mapping(name, seed, house, knobs.frames, 0.5, house.items, route, [], [])
    scenario_from_dict(mapping)
    return mapping, WorldNotes(seed, attempt, tuple(house.rooms), ())


def _appear_pairs(
    rng: random.Random, house: House, shelver: Shelver, views: dict[str, list[tuple[float, float]]]
) -> list[tuple[Item, Item]]:
    """(small, cover) pairs: objects placed just behind a taller one as seen from their
    fixture's viewpoint, candidates for the appearance behind an occluder (up to three: one is
    scripted to appear, the others stay ordinary objects behind their covers)."""
    fixtures = house.fixtures()
    appear_pairs: list[tuple[Item, Item]] = []
    coverable = [
        p
        for p in fixtures
        if TALL_ON[p.label] and not any(i.on == p.id for i in house.items if i.id in house.behind)
    ]
    rng.shuffle(coverable)
    for piece in coverable:
        if len(appear_pairs) >= 3:
            break
        small = rng.choice([label for label in SMALL_BEHIND if label in ON[piece.label]] or ["cup"])
        pair = shelver.place_behind(
            piece.id, small, rng.choice(TALL_ON[piece.label]), views[piece.id][0]
        )
        if pair is not None:
            appear_pairs.append(pair)
    if not appear_pairs:
        raise _Resample("no fixture has room for an object behind a taller one")
    return appear_pairs


def _notes(
    seed: int,
    attempt: int,
    house: House,
    route: Route,
    spans: list[tuple[int, int]],
    sights: Sightings,
    scripter: Scripter,
) -> WorldNotes:
    """What the generator put into the world: visits, revisit intervals, covers, hard events."""
    visit_firsts: dict[str, list[int]] = {}
    for visit, (start, _) in zip(route.visits, spans, strict=True):
        visit_firsts.setdefault(visit.fixture, []).append(start)
    intervals = tuple(
        later - earlier
        for firsts in visit_firsts.values()
        for earlier, later in itertools.pairwise(firsts)
    )
    behind = {small: big for small, big in house.behind.items()}
    planned = {}
    for small in behind:
        share = hidden_fraction(list(sights.pixels[small]), list(sights.in_view[small]))
        if share is not None:
            planned[small] = round(share, 3)
    notes = WorldNotes(
        seed,
        attempt,
        tuple(house.rooms),
        tuple(scripter.hard),
        {key: tuple(value) for key, value in visit_firsts.items()},
        intervals,
        behind,
        planned,
    )
    return notes


def _attempt(
    seed: int, attempt: int, knobs: WorldKnobs, active: bool
) -> tuple[dict[str, Any], WorldNotes]:
    rng = random.Random(f"pbdag-world:{seed}:{attempt}:{'active' if active else 'dynamic'}")
    name = f"gen-active-{seed}" if active else f"gen-{seed}"
    house = build_house(rng, knobs)
    if house is None:
        raise _Resample("the drawn furniture does not fit")
    planner = Planner(house)
    views = {p.id: planner.viewpoints(p, rng) for p in house.fixtures()}
    if any(not found for found in views.values()):
        raise _Resample("a fixture cannot be seen from the walkable floor")
    shelver = Shelver(rng, house)
    _items(rng, house, shelver, knobs, views, active)
    if active:
        return _active_world(rng, name, seed, attempt, knobs, house, planner, views)
    fixtures = house.fixtures()
    visits = max(2, min(round(knobs.frames / FRAMES_PER_VISIT), 3 * len(fixtures)))
    per_visit = knobs.frames / visits
    gaps = (
        max(2, round(knobs.revisit_frames[0] / per_visit)),
        max(2, round(knobs.revisit_frames[1] / per_visit)),
    )
    order = visit_order(rng, _tour(rng, house), visits, gaps)
    route = build_route(rng, planner, views, order, PAUSE_SHARE)
    spans = visit_frames(route, knobs.frames, float(CAMERA["eye_height"]))
    people = _people(rng, planner, house, route, spans, knobs.people, knobs.frames)

    appear_pairs = _appear_pairs(rng, house, shelver, views)
    covers = set(house.behind.values())
    plain = [i for i in house.items if i.id not in covers and i.id not in house.behind]
    rng.shuffle(plain)

    ghosts, transfers, moves = destinations(house, shelver, plain, rng)
    planning = _mapping(
        name, seed, house, knobs.frames, 0.25, [*house.items, *ghosts], route, people, []
    )
    scenario = scenario_from_dict(planning)
    sights = sightings(scenario, house.rooms)

    scripter, listed = scripted_events(
        rng, sights, knobs, house, appear_pairs, plain, transfers, moves
    )
    mapping = _mapping(
        name, seed, house, knobs.frames, 0.25, listed, route, people, scripter.events
    )
    scenario_from_dict(mapping)
    notes = _notes(seed, attempt, house, route, spans, sights, scripter)
    return mapping, notes


def generate_world_with_notes(
    seed: int, *, active: bool = False, knobs: WorldKnobs | None = None
) -> tuple[dict[str, Any], WorldNotes]:
    """The scenario mapping of world `seed` and what the generator put into it."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    knobs = knobs or (active_knobs() if active else WorldKnobs())
    reasons: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        try:
            return _attempt(seed, attempt, knobs, active)
        except (_Resample, Unscriptable, ScenarioError) as error:
            reasons.append(f"{type(error).__name__}: {error}")
    summary = "; ".join(sorted(set(reasons))[:6])
    raise GenerationError(f"seed {seed}: no valid world in {MAX_ATTEMPTS} draws ({summary})")


def generate_world(
    seed: int, *, active: bool = False, knobs: WorldKnobs | None = None
) -> dict[str, Any]:
    """The scenario mapping of world `seed` (name `gen-<seed>`, active: `gen-active-<seed>`)."""
    return generate_world_with_notes(seed, active=active, knobs=knobs)[0]
