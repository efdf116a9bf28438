"""A house plan: rooms split by interior walls with door gaps, furniture and occluders (the
objects on the furniture are `sim.generator.objects`)."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from sim.generator.knobs import WorldKnobs

Rect = tuple[float, float, float, float]  # x0, y0, x1, y1
WALL_HEIGHT = 2.6
WALL_THICKNESS = 0.1
DOOR_WIDTH = (0.9, 1.0)
DOOR_CLEARANCE_M = 0.9  # no furniture this close to a door gap, on either side
WALKWAY_M = 0.7  # free floor kept between free-standing pieces of furniture
EDGE_M = 0.07  # furniture stands this far from a wall line (half the wall and a little)

# Object classes of the shipped worlds, with their sizes [m].
ROOM_KINDS = ("kitchen", "living", "bedroom", "study")


@dataclass
class Piece:
    """A floor-standing box: a fixture (label of the taxonomy) or an occluder (chair)."""

    id: str
    label: str
    center: tuple[float, float]
    size: tuple[float, float, float]
    room: int
    fixture: bool = True
    front: tuple[float, float] | None = None  # unit vector to the open side (None: all round)

    def rect(self, grow: float = 0.0) -> Rect:
        """The footprint, grown by `grow` on every side."""
        hx, hy = self.size[0] / 2 + grow, self.size[1] / 2 + grow
        return (self.center[0] - hx, self.center[1] - hy, self.center[0] + hx, self.center[1] + hy)


@dataclass
class Item:
    """An object on a fixture's top at offset `at`."""

    id: str
    label: str
    size: tuple[float, float, float]
    on: str
    at: tuple[float, float]


@dataclass
class Wall:
    """An interior wall line and its door gaps (centre along the line, width)."""

    start: tuple[float, float]
    end: tuple[float, float]
    doors: list[tuple[float, float]]

    def segments(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The solid pieces between the door gaps."""
        (x0, y0), (x1, y1) = self.start, self.end
        length = math.hypot(x1 - x0, y1 - y0)
        ux, uy = (x1 - x0) / length, (y1 - y0) / length
        cuts = [0.0]
        for centre, width in sorted(self.doors):
            cuts += [centre - width / 2, centre + width / 2]
        cuts.append(length)
        pieces = []
        for a, b in zip(cuts[::2], cuts[1::2], strict=True):
            if b - a > 0.05:
                pieces.append(((x0 + ux * a, y0 + uy * a), (x0 + ux * b, y0 + uy * b)))
        return pieces

    def door_points(self) -> list[tuple[float, float]]:
        """The centre of each door gap."""
        (x0, y0), (x1, y1) = self.start, self.end
        length = math.hypot(x1 - x0, y1 - y0)
        return [(x0 + (x1 - x0) * c / length, y0 + (y1 - y0) * c / length) for c, _ in self.doors]


@dataclass
class House:
    """Everything static of a generated world."""

    size: tuple[float, float]
    rooms: list[Rect]
    kinds: list[str]
    walls: list[Wall]
    pieces: list[Piece] = field(default_factory=list)
    items: list[Item] = field(default_factory=list)
    behind: dict[str, str] = field(default_factory=dict)

    def fixtures(self) -> list[Piece]:
        """The fixtures (no chairs)."""
        return [piece for piece in self.pieces if piece.fixture]

    def piece(self, piece_id: str) -> Piece:
        """The piece with this id."""
        return next(piece for piece in self.pieces if piece.id == piece_id)

    def room_of(self, x: float, y: float) -> int:
        """Index of the room holding a point (the nearest one on a wall line)."""
        best, best_distance = 0, math.inf
        for index, (x0, y0, x1, y1) in enumerate(self.rooms):
            distance = math.hypot(max(x0 - x, 0, x - x1), max(y0 - y, 0, y - y1))
            if distance < best_distance:
                best, best_distance = index, distance
        return best


def overlap(a: Rect, b: Rect) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _inside(inner: Rect, outer: Rect) -> bool:
    return (
        inner[0] >= outer[0]
        and inner[1] >= outer[1]
        and inner[2] <= outer[2]
        and inner[3] <= outer[3]
    )


def split_rooms(
    rng: random.Random, knobs: WorldKnobs
) -> tuple[tuple[float, float], list[Rect], list[Wall]]:
    """The house rectangle cut into `knobs.rooms` rooms; each cut is a wall with door gaps."""
    aspect = rng.uniform(1.2, 1.6)
    sx = round(math.sqrt(knobs.area_m2 * aspect), 1)
    sy = round(knobs.area_m2 / sx, 1)
    rooms: list[Rect] = [(0.0, 0.0, sx, sy)]
    walls: list[Wall] = []
    while len(rooms) < knobs.rooms:
        rooms.sort(key=lambda r: (r[2] - r[0]) * (r[3] - r[1]))
        x0, y0, x1, y1 = rooms.pop()
        vertical = (x1 - x0) >= (y1 - y0)  # cut across the longer side
        low, high = (x0, x1) if vertical else (y0, y1)
        cut = round(low + (high - low) * rng.uniform(0.4, 0.6), 2)
        if vertical:
            rooms += [(x0, y0, cut, y1), (cut, y0, x1, y1)]
            start, end = (cut, y0), (cut, y1)
        else:
            rooms += [(x0, y0, x1, cut), (x0, cut, x1, y1)]
            start, end = (x0, cut), (x1, cut)
        length = math.hypot(end[0] - start[0], end[1] - start[1])
        doors: list[tuple[float, float]] = []
        count = max(1, min(knobs.doors_per_wall, int(length // 2.2)))
        # Door gaps spread along the wall, at least 0.35 m from its ends.
        for index in range(count):
            width = round(rng.uniform(*DOOR_WIDTH), 2)
            share_low, share_high = index / count, (index + 1) / count
            low_c = max(0.35 + width / 2, length * share_low + width / 2 + 0.2)
            high_c = min(length - 0.35 - width / 2, length * share_high - width / 2 - 0.2)
            centre = round(rng.uniform(low_c, max(low_c, high_c)), 2)
            doors.append((centre, width))
        walls.append(Wall(start, end, doors))
    rooms.sort(key=lambda r: (r[1], r[0]))
    return (sx, sy), rooms, walls


def _door_zones(walls: list[Wall]) -> list[Rect]:
    """Floor kept free around each door gap."""
    zones = []
    for wall in walls:
        for (x, y), (_, width) in zip(wall.door_points(), wall.doors, strict=True):
            reach = max(width / 2 + 0.15, DOOR_CLEARANCE_M)
            zones.append((x - reach, y - reach, x + reach, y + reach))
    return zones


class Furnisher:
    """Places the furniture of one house, room by room, against walls or free-standing."""

    def __init__(self, rng: random.Random, house: House) -> None:
        self.rng, self.house = rng, house
        self.zones = _door_zones(house.walls)
        self.counts: dict[str, int] = {}

    def _id(self, label: str) -> str:
        self.counts[label] = self.counts.get(label, 0) + 1
        return f"{label}_{self.counts[label]}"

    def _clear(self, rect: Rect, room: int, gap: float, ignore: tuple[str, ...] = ()) -> bool:
        x0, y0, x1, y1 = self.house.rooms[room]
        if not _inside(
            rect, (x0 + EDGE_M - 1e-9, y0 + EDGE_M - 1e-9, x1 - EDGE_M + 1e-9, y1 - EDGE_M + 1e-9)
        ):
            return False
        if any(overlap(rect, zone) for zone in self.zones):
            return False
        grown = (rect[0] - gap, rect[1] - gap, rect[2] + gap, rect[3] + gap)
        return not any(
            overlap(grown, piece.rect()) for piece in self.house.pieces if piece.id not in ignore
        )

    def against_wall(
        self, label: str, room: int, length: float, depth: float, height: float, tries: int = 40
    ) -> Piece | None:
        """A piece with its back to one of the room's walls, facing into the room."""
        x0, y0, x1, y1 = self.house.rooms[room]
        for _ in range(tries):
            side = self.rng.choice("SNWE")
            if side in "SN":
                if x1 - x0 < length + 2 * EDGE_M:
                    continue
                cx = self.rng.uniform(x0 + EDGE_M + length / 2, x1 - EDGE_M - length / 2)
                cy = y0 + EDGE_M + depth / 2 if side == "S" else y1 - EDGE_M - depth / 2
                size = (length, depth, height)
                front = (0.0, 1.0) if side == "S" else (0.0, -1.0)
            else:
                if y1 - y0 < length + 2 * EDGE_M:
                    continue
                cy = self.rng.uniform(y0 + EDGE_M + length / 2, y1 - EDGE_M - length / 2)
                cx = x0 + EDGE_M + depth / 2 if side == "W" else x1 - EDGE_M - depth / 2
                size = (depth, length, height)
                front = (1.0, 0.0) if side == "W" else (-1.0, 0.0)
            piece = Piece(
                self._id(label), label, (round(cx, 2), round(cy, 2)), size, room, True, front
            )
            if self._clear(piece.rect(), room, WALKWAY_M):
                self.house.pieces.append(piece)
                return piece
            self.counts[label] -= 1
        return None

    def free_standing(
        self, label: str, room: int, size: tuple[float, float, float], chairs: int, tries: int = 40
    ) -> Piece | None:
        """A table away from the walls, with chairs (occluders) along its long sides."""
        x0, y0, x1, y1 = self.house.rooms[room]
        for _ in range(tries):
            turned = self.rng.random() < 0.5
            sx, sy = (size[1], size[0]) if turned else (size[0], size[1])
            margin = 0.6 + (0.5 if chairs else 0.0)
            if x1 - x0 < sx + 2 * margin or y1 - y0 < sy + 2 * margin:
                return None
            cx = round(self.rng.uniform(x0 + margin + sx / 2, x1 - margin - sx / 2), 2)
            cy = round(self.rng.uniform(y0 + margin + sy / 2, y1 - margin - sy / 2), 2)
            table = Piece(self._id(label), label, (cx, cy), (sx, sy, size[2]), room, True, None)
            seats = []
            for index in range(chairs):
                along = (index // 2 + 0.5) / max(1, (chairs + 1) // 2) - 0.5
                sign = 1.0 if index % 2 else -1.0
                offset = 0.05 + 0.225
                if sx >= sy:
                    at = (cx + along * sx, cy + sign * (sy / 2 + offset))
                else:
                    at = (cx + sign * (sx / 2 + offset), cy + along * sy)
                seats.append(at)
            chair_pieces = [
                Piece(
                    f"chair_{self.counts.get('chair', 0) + k + 1}",
                    "chair",
                    (round(x, 2), round(y, 2)),
                    (0.45, 0.45, 0.95),
                    room,
                    False,
                )
                for k, (x, y) in enumerate(seats)
            ]
            ok = self._clear(table.rect(0.55), room, 0.3)
            ok = ok and all(self._clear(chair.rect(), room, 0.5) for chair in chair_pieces)
            if ok:
                self.counts["chair"] = self.counts.get("chair", 0) + len(chair_pieces)
                self.house.pieces += [table, *chair_pieces]
                return table
            self.counts[label] -= 1
        return None

    def beside(self, anchor: Piece, label: str, size: tuple[float, float, float]) -> Piece | None:
        """A nightstand beside the head end of a bed (flush with the wall the bed backs onto)."""
        assert anchor.front is not None
        fx, fy = anchor.front
        for sign in (1.0, -1.0) if self.rng.random() < 0.5 else (-1.0, 1.0):
            if fx == 0.0:  # the bed's back is a south or north wall: stand beside along x
                cx = anchor.center[0] + sign * (anchor.size[0] / 2 + 0.08 + size[0] / 2)
                cy = anchor.center[1] - fy * (anchor.size[1] / 2 - size[1] / 2)
            else:
                cy = anchor.center[1] + sign * (anchor.size[1] / 2 + 0.08 + size[1] / 2)
                cx = anchor.center[0] - fx * (anchor.size[0] / 2 - size[0] / 2)
            piece = Piece(
                self._id(label),
                label,
                (round(cx, 2), round(cy, 2)),
                size,
                anchor.room,
                True,
                anchor.front,
            )
            if self._clear(piece.rect(), anchor.room, 0.05, ignore=(anchor.id,)) and not overlap(
                piece.rect(0.02), anchor.rect()
            ):
                self.house.pieces.append(piece)
                return piece
            self.counts[label] -= 1
        return None


def furnish_room(furnisher: Furnisher, room: int, kind: str, budget: int) -> int:
    """Put up to `budget` fixtures of a room kind into a room; the count placed."""
    rng = furnisher.rng
    placed: list[Piece | None] = []

    def room_left() -> bool:
        return sum(piece is not None for piece in placed) < budget

    if kind == "kitchen":
        size = (rng.choice((1.2, 1.4, 1.6)), rng.choice((0.8, 0.9)), 0.75)
        placed.append(furnisher.free_standing("table", room, size, rng.choice((2, 4))))
        if room_left():
            length = rng.choice((1.8, 2.0, 2.4))
            placed.append(furnisher.against_wall("counter", room, length, 0.6, 0.9))
    elif kind == "living":
        sofa = furnisher.against_wall("sofa", room, rng.choice((1.8, 2.0)), 0.9, 0.45)
        placed.append(sofa)
        if sofa is not None and sofa.front is not None and room_left():
            # A low coffee table 0.45 m in front of the sofa.
            fx, fy = sofa.front
            length = 1.0
            cx = sofa.center[0] + fx * (sofa.size[0] / 2 + 0.45 + 0.3)
            cy = sofa.center[1] + fy * (sofa.size[1] / 2 + 0.45 + 0.3)
            size = (length, 0.6, 0.45) if fx == 0.0 else (0.6, length, 0.45)
            table = Piece(
                furnisher._id("table"),
                "table",
                (round(cx, 2), round(cy, 2)),
                size,
                room,
                True,
                None,
            )
            if furnisher._clear(table.rect(), room, 0.4, ignore=(sofa.id,)):
                furnisher.house.pieces.append(table)
                placed.append(table)
            else:
                furnisher.counts["table"] -= 1
        if room_left():
            placed.append(
                furnisher.against_wall(
                    "shelf", room, rng.choice((1.0, 1.2)), 0.45, rng.choice((1.0, 1.1))
                )
            )
    elif kind == "bedroom":
        bed = furnisher.against_wall("bed", room, 1.6, 2.0, 0.55)
        placed.append(bed)
        if bed is not None and room_left():
            placed.append(furnisher.beside(bed, "cabinet", (0.5, 0.45, 0.6)))
        if room_left():
            placed.append(furnisher.against_wall("shelf", room, 1.0, 0.45, 1.0))
    else:  # study
        desk = furnisher.against_wall("desk", room, rng.choice((1.2, 1.4)), 0.7, 0.75)
        placed.append(desk)
        if desk is not None and desk.front is not None:
            fx, fy = desk.front
            chair = Piece(
                f"chair_{furnisher.counts.get('chair', 0) + 1}",
                "chair",
                (
                    round(desk.center[0] + fx * (desk.size[0] / 2 + 0.3), 2),
                    round(desk.center[1] + fy * (desk.size[1] / 2 + 0.3), 2),
                ),
                (0.45, 0.45, 0.95),
                room,
                False,
            )
            if furnisher._clear(chair.rect(), room, 0.0, ignore=(desk.id,)):
                furnisher.counts["chair"] = furnisher.counts.get("chair", 0) + 1
                furnisher.house.pieces.append(chair)
        if room_left():
            placed.append(furnisher.against_wall("shelf", room, 1.2, 0.45, 1.0))
        if room_left():
            placed.append(furnisher.against_wall("cabinet", room, 0.8, 0.45, 0.8))
    return sum(piece is not None for piece in placed)


def build_house(rng: random.Random, knobs: WorldKnobs) -> House | None:
    """Rooms, walls and furniture; None when the drawn fixture count does not fit."""
    size, rooms, walls = split_rooms(rng, knobs)
    # Every house has a kitchen and a living room first, then bedrooms and studies.
    extra = ["bedroom", "study"]
    rng.shuffle(extra)
    kinds = (["kitchen", "living"] + extra * len(rooms))[: len(rooms)]
    rng.shuffle(kinds)
    house = House(size, rooms, kinds, walls)
    furnisher = Furnisher(rng, house)
    wanted = rng.randint(*knobs.fixtures)
    for round_index in range(3):
        for room, kind in enumerate(kinds):
            left = wanted - len(house.fixtures())
            if left <= 0:
                break
            if round_index == 0:
                furnish_room(furnisher, room, kind, min(left, 3))
            else:  # extra shelves and cabinets against free walls
                label = rng.choice(("shelf", "cabinet", "counter" if kind == "kitchen" else "desk"))
                dims = {
                    "shelf": (1.0, 0.45, 1.0),
                    "cabinet": (0.8, 0.45, 0.8),
                    "counter": (1.6, 0.6, 0.9),
                    "desk": (1.2, 0.7, 0.75),
                }[label]
                furnisher.against_wall(label, room, *dims)
    if not knobs.fixtures[0] <= len(house.fixtures()) <= knobs.fixtures[1]:
        return None
    return house
