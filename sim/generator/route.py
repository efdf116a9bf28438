"""The robot's route through a generated house: viewpoints, a visit order with revisits, a
walkable waypoint polyline through the doors, and people who step into the robot's views."""

from __future__ import annotations

import itertools
import math
import random
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csgraph

from sim.free_space import FreeSpace
from sim.generator.layout import WALL_HEIGHT, WALL_THICKNESS, House, Piece
from sim.world import Box, World

ROBOT_RADIUS_M = 0.3  # waypoints and walkers keep this far from furniture and walls
CELL_M = 0.1
VIEW_DISTANCE_M = (0.7, 2.2)  # from a fixture's footprint to a viewpoint
FRAMES_PER_METRE = 4  # people walk about 1 m/s at 4 frames per second


@dataclass(frozen=True)
class Visit:
    """A stop of the route: where the robot stands and the fixture it looks at."""

    fixture: str
    at: tuple[float, float]
    look_at: tuple[float, float, float]


@dataclass(frozen=True)
class Route:
    """The waypoint polyline (closed) and, per waypoint, the visit it is (None: on the way)."""

    points: tuple[tuple[float, float], ...]
    look_at: tuple[tuple[float, float, float], ...]
    pause: tuple[float, ...]
    visit_of_point: tuple[int | None, ...]
    visits: tuple[Visit, ...]


def static_world(house: House) -> World:
    """The house as boxes: fixtures, walls and chairs (for free space and line-of-sight tests)."""
    fixtures = tuple(
        Box(p.id, p.label, (p.center[0], p.center[1], p.size[2] / 2), p.size, kind="fixture")
        for p in house.pieces
        if p.fixture
    )
    occluders = [
        Box(p.id, p.label, (p.center[0], p.center[1], p.size[2] / 2), p.size, kind="occluder")
        for p in house.pieces
        if not p.fixture
    ]
    for index, wall in enumerate(house.walls):
        for piece, ((x0, y0), (x1, y1)) in enumerate(wall.segments()):
            length = math.hypot(x1 - x0, y1 - y0)
            occluders.append(
                Box(
                    f"wall_{index}_{piece}",
                    "wall",
                    ((x0 + x1) / 2, (y0 + y1) / 2, WALL_HEIGHT / 2),
                    (length, WALL_THICKNESS, WALL_HEIGHT),
                    math.atan2(y1 - y0, x1 - x0),
                    "occluder",
                )
            )
    return World((house.size[0], house.size[1], WALL_HEIGHT + 0.1), fixtures, (), tuple(occluders))


class Planner:
    """Free space of a house: viewpoints, shortest walkable paths, straightened."""

    def __init__(self, house: House) -> None:
        self.house = house
        self.world = static_world(house)
        self.space = FreeSpace(self.world, ROBOT_RADIUS_M, CELL_M)
        _, labels = csgraph.connected_components(self.space.graph, directed=False)
        self.labels = labels
        self.main = int(np.bincount(labels).argmax()) if len(labels) else -1
        self.centres = (self.space.cell_rc[:, ::-1] + 0.5) * CELL_M  # (n, 2) x, y

    def _blocked(self, a: tuple[float, float], b: tuple[float, float], skip: str) -> bool:
        """Whether the sight line a -> b crosses a wall or another fixture's footprint."""
        steps = max(int(math.hypot(b[0] - a[0], b[1] - a[1]) / 0.05), 1)
        boxes = [
            box
            for box in (*self.world.fixtures, *self.world.occluders)
            if box.id != skip and box.label != "chair"
        ]
        for k in range(steps):
            x, y = a[0] + (b[0] - a[0]) * k / steps, a[1] + (b[1] - a[1]) * k / steps
            for box in boxes:
                c, s = math.cos(box.yaw), math.sin(box.yaw)
                dx, dy = x - box.center[0], y - box.center[1]
                if (
                    abs(c * dx + s * dy) <= box.size[0] / 2
                    and abs(-s * dx + c * dy) <= box.size[1] / 2
                ):
                    return True
        return False

    def viewpoints(
        self, piece: Piece, rng: random.Random, count: int = 3
    ) -> list[tuple[float, float]]:
        """Up to `count` good, mutually distinct places to look at a fixture from."""
        x0, y0, x1, y1 = piece.rect()
        px = np.clip(self.centres[:, 0], x0, x1)
        py = np.clip(self.centres[:, 1], y0, y1)
        gap = np.hypot(self.centres[:, 0] - px, self.centres[:, 1] - py)
        dx = self.centres[:, 0] - piece.center[0]
        dy = self.centres[:, 1] - piece.center[1]
        reach = np.hypot(dx, dy)
        ok = (gap >= VIEW_DISTANCE_M[0]) & (gap <= VIEW_DISTANCE_M[1]) & (self.labels == self.main)
        rx0, ry0, rx1, ry1 = self.house.rooms[piece.room]
        ok &= (self.centres[:, 0] > rx0) & (self.centres[:, 0] < rx1)
        ok &= (self.centres[:, 1] > ry0) & (self.centres[:, 1] < ry1)
        facing = np.ones_like(reach)
        if piece.front is not None:
            facing = (dx * piece.front[0] + dy * piece.front[1]) / np.maximum(reach, 1e-9)
            ok &= facing >= math.cos(math.radians(55))
        score = (
            np.abs(gap - 1.3)
            + 0.6 * (1.0 - facing)
            + 0.3 * np.array([rng.random() for _ in range(len(gap))])
        )
        chosen: list[tuple[float, float]] = []
        for node in np.argsort(np.where(ok, score, np.inf)):
            if not ok[node] or len(chosen) >= count:
                break
            point = (float(self.centres[node, 0]), float(self.centres[node, 1]))
            if any(math.hypot(point[0] - q[0], point[1] - q[1]) < 0.5 for q in chosen):
                continue
            if self._blocked(point, piece.center, piece.id):
                continue
            chosen.append((round(point[0], 2), round(point[1], 2)))
        return chosen

    def _free(self, x: float, y: float) -> bool:
        col, row = int(x / CELL_M), int(y / CELL_M)
        if not (0 <= row < self.space.rows and 0 <= col < self.space.cols):
            return False
        return bool(self.space.free[row, col])

    def _straight(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        steps = max(int(math.hypot(b[0] - a[0], b[1] - a[1]) / 0.04), 1)
        return all(
            self._free(a[0] + (b[0] - a[0]) * k / steps, a[1] + (b[1] - a[1]) * k / steps)
            for k in range(steps + 1)
        )

    def path(self, a: tuple[float, float], b: tuple[float, float]) -> list[tuple[float, float]]:
        """Corner points strictly between a and b of a short free path (straightened)."""
        if self._straight(a, b):
            return []
        start = self.space.nearest(*a)
        nodes = self.space.path(start, *b)
        cells = [a, *(self.space.xy(node) for node in nodes), b]
        corners: list[tuple[float, float]] = []
        index = 0
        while index < len(cells) - 1:
            reach = len(cells) - 1
            while reach > index + 1 and not self._straight(cells[index], cells[reach]):
                reach -= 1
            if reach < len(cells) - 1:
                corners.append((round(cells[reach][0], 2), round(cells[reach][1], 2)))
            index = reach
        return corners

    def distance(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Length of the walkable path a -> b."""
        points = [a, *self.path(a, b), b]
        return sum(math.dist(p, q) for p, q in itertools.pairwise(points))


def visit_order(
    rng: random.Random, tour: list[str], count: int, gap_visits: tuple[int, int]
) -> list[str]:
    """`count` visits: the tour in order, with every visited fixture revisited after a drawn gap."""
    order: list[str] = []
    pending: list[tuple[int, float, str]] = []  # (due position, tie-break, fixture)
    next_new = 0
    while len(order) < count:
        last = order[-1] if order else None
        due = sorted(item for item in pending if item[0] <= len(order) and item[2] != last)
        waiting = sorted(item for item in pending if item[2] != last)
        if due:
            chosen = due[0]
        elif next_new < len(tour):
            chosen = (0, 0.0, tour[next_new])
            next_new += 1
        elif waiting:
            chosen = waiting[0]
        else:
            break
        if chosen in pending:
            pending.remove(chosen)
        order.append(chosen[2])
        pending.append((len(order) - 1 + rng.randint(*gap_visits), rng.random(), chosen[2]))
    return order


def build_route(
    rng: random.Random,
    planner: Planner,
    views: dict[str, list[tuple[float, float]]],
    order: list[str],
    pause_total: float,
) -> Route:
    """The closed polyline through the visits of `order`, via free-space paths between them."""
    house = planner.house
    visits: list[Visit] = []
    for position, fixture in enumerate(order):
        piece = house.piece(fixture)
        at = views[fixture][0] if position == order.index(fixture) else rng.choice(views[fixture])
        visits.append(Visit(fixture, at, (piece.center[0], piece.center[1], piece.size[2])))
    points: list[tuple[float, float]] = []
    looks: list[tuple[float, float, float]] = []
    pauses: list[float] = []
    of_point: list[int | None] = []
    pause = round(pause_total / len(visits), 4)
    for index, visit in enumerate(visits):
        following = visits[(index + 1) % len(visits)]
        points.append(visit.at)
        looks.append(visit.look_at)
        pauses.append(pause)
        of_point.append(index)
        for corner in planner.path(visit.at, following.at):
            points.append(corner)
            looks.append(following.look_at)
            pauses.append(0.0)
            of_point.append(None)
    return Route(tuple(points), tuple(looks), tuple(pauses), tuple(of_point), tuple(visits))


def visit_frames(route: Route, frames: int, eye_height: float) -> list[tuple[int, int]]:
    """Per visit: the first and last frame of its pause (the trajectory's own timing, one lap)."""
    eyes = np.array(
        [(x, y, eye_height) for x, y in route.points] + [(*route.points[0], eye_height)]
    )
    lengths = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    stops = np.asarray(route.pause, dtype=np.float64)
    moving = (1.0 - stops.sum()) * lengths / max(float(lengths.sum()), 1e-12)
    starts = np.concatenate([[0.0], np.cumsum(stops + moving)])
    spans = []
    for point, visit in enumerate(route.visit_of_point):
        if visit is None:
            continue
        first = math.ceil(starts[point] * frames - 1e-9)
        last = max(first, math.floor((starts[point] + stops[point]) * frames + 1e-9))
        spans.append((min(first, frames - 1), min(last, frames - 1)))
    return spans


def walker(
    planner: Planner,
    start: tuple[float, float],
    stand: tuple[float, float],
    arrive: int,
    leave: int,
    frames: int,
) -> list[tuple[int, tuple[float, float]]] | None:
    """Keyframes of a person walking start -> stand, staying [arrive, leave], walking back."""
    there = [start, *planner.path(start, stand), stand]
    lengths = [math.dist(p, q) for p, q in itertools.pairwise(there)]
    walk = sum(lengths)
    first = arrive - math.ceil(walk * FRAMES_PER_METRE)
    last = leave + math.ceil(walk * FRAMES_PER_METRE)
    if first < 0 or last >= frames:
        return None
    keys: list[tuple[int, tuple[float, float]]] = []
    elapsed = 0.0
    for point, length in zip(there, [0.0, *lengths], strict=True):
        elapsed += length
        keys.append((first + round(elapsed * FRAMES_PER_METRE), point))
    keys[-1] = (arrive, stand)
    back = list(reversed(there))
    elapsed = 0.0
    for point, length in zip(back, [0.0, *reversed(lengths)], strict=True):
        elapsed += length
        keys.append((leave + round(elapsed * FRAMES_PER_METRE), point))
    keys[-1] = (last, back[-1])
    # Frames never run backwards (rounding): keep them non-decreasing.
    for index in range(1, len(keys)):
        if keys[index][0] < keys[index - 1][0]:
            keys[index] = (keys[index - 1][0], keys[index][1])
    return keys


def standing_spot(planner: Planner, visit: Visit, piece: Piece) -> tuple[float, float] | None:
    """A free spot between a viewpoint and its fixture where a person blocks part of the view."""
    for share in (0.5, 0.4, 0.6, 0.3, 0.7):
        x = visit.at[0] + share * (piece.center[0] - visit.at[0])
        y = visit.at[1] + share * (piece.center[1] - visit.at[1])
        if planner._free(x, y) and math.dist((x, y), visit.at) >= 0.6:
            return (round(x, 2), round(y, 2))
    return None
