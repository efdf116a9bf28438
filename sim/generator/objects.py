"""The objects on a house's furniture: their classes and sizes, what stands on which fixture,
and the placer that puts them on fixture tops without overlaps."""

from __future__ import annotations

import math
import random

from sim.generator.layout import House, Item, Rect, overlap

SIZES: dict[str, tuple[float, float, float]] = {
    "mug": (0.08, 0.08, 0.10),
    "cup": (0.08, 0.08, 0.10),
    "book": (0.22, 0.16, 0.04),
    "bottle": (0.07, 0.07, 0.25),
    "bowl": (0.16, 0.16, 0.07),
    "plate": (0.24, 0.24, 0.025),
    "remote": (0.18, 0.06, 0.03),
    "phone": (0.15, 0.075, 0.015),
    "keys": (0.08, 0.05, 0.02),
    "laptop": (0.34, 0.24, 0.03),
    "plant": (0.14, 0.14, 0.25),
    "vase": (0.12, 0.12, 0.28),
    "box": (0.20, 0.12, 0.30),
    "glasses": (0.14, 0.05, 0.04),
    "lamp": (0.15, 0.15, 0.35),
}
TALL = ("bottle", "vase", "plant", "box", "lamp")
# What plausibly lies on each fixture class of the taxonomy.
ON: dict[str, tuple[str, ...]] = {
    "table": ("mug", "cup", "plate", "bowl", "book", "remote", "keys", "glasses", "phone"),
    "desk": ("laptop", "mug", "book", "phone", "keys", "glasses", "cup"),
    "counter": ("bottle", "bowl", "cup", "mug", "plate", "keys"),
    "bed": ("book", "phone", "glasses"),
    "shelf": ("book", "box", "vase", "plant", "mug"),
    "cabinet": ("glasses", "phone", "book", "keys", "cup"),
    "sofa": ("remote", "book", "phone"),
}
# Covers: taller and wider than a mug, so a mug just behind one is hidden from the front.
TALL_ON: dict[str, tuple[str, ...]] = {
    "table": ("vase", "box"),
    "desk": ("lamp", "plant"),
    "counter": ("box", "plant"),
    "shelf": ("vase", "plant", "box"),
    "cabinet": ("lamp", "vase"),
    "bed": (),
    "sofa": (),
}


def _spot(
    rng: random.Random,
    top: tuple[float, float],
    size: tuple[float, float, float],
    taken: list[Rect],
    tries: int = 30,
) -> tuple[float, float] | None:
    """A free offset on a top of `top` (x, y extents) for an object of `size`."""
    hx, hy = size[0] / 2, size[1] / 2
    room_x, room_y = top[0] / 2 - hx - 0.02, top[1] / 2 - hy - 0.02
    if room_x < 0 or room_y < 0:
        return None
    for _ in range(tries):
        at = (round(rng.uniform(-room_x, room_x), 3), round(rng.uniform(-room_y, room_y), 3))
        rect = (at[0] - hx - 0.03, at[1] - hy - 0.03, at[0] + hx + 0.03, at[1] + hy + 0.03)
        if not any(overlap(rect, other) for other in taken):
            return at
    return None


class Shelver:
    """Puts objects on fixture tops without overlaps; remembers every spot ever used."""

    def __init__(self, rng: random.Random, house: House) -> None:
        self.rng, self.house = rng, house
        self.taken: dict[str, list[Rect]] = {piece.id: [] for piece in house.fixtures()}
        self.counts: dict[str, int] = {}

    def new_id(self, label: str) -> str:
        """A fresh object id of this label."""
        self.counts[label] = self.counts.get(label, 0) + 1
        return f"{label}_{self.counts[label]}"

    def reserve(
        self, fixture: str, at: tuple[float, float], size: tuple[float, float, float]
    ) -> None:
        """Mark a spot as used from now on."""
        hx, hy = size[0] / 2, size[1] / 2
        self.taken[fixture].append((at[0] - hx, at[1] - hy, at[0] + hx, at[1] + hy))

    def spot(self, fixture: str, size: tuple[float, float, float]) -> tuple[float, float] | None:
        """A free spot on a fixture for an object of this size (reserved)."""
        piece = self.house.piece(fixture)
        at = _spot(self.rng, piece.size[:2], size, self.taken[fixture])
        if at is not None:
            self.reserve(fixture, at, size)
        return at

    def place(self, fixture: str, label: str) -> Item | None:
        """A new object of `label` on a free spot of the fixture."""
        size = SIZES[label]
        at = self.spot(fixture, size)
        if at is None:
            return None
        item = Item(self.new_id(label), label, size, fixture, at)
        self.house.items.append(item)
        return item

    def place_behind(
        self, fixture: str, small: str, tall: str, toward: tuple[float, float]
    ) -> tuple[Item, Item] | None:
        """A small object with a taller one just in front of it, as seen from `toward`."""
        piece = self.house.piece(fixture)
        small_size, tall_size = SIZES[small], SIZES[tall]
        dx, dy = toward[0] - piece.center[0], toward[1] - piece.center[1]
        norm = math.hypot(dx, dy) or 1.0
        ux, uy = dx / norm, dy / norm
        for _ in range(20):
            at = _spot(self.rng, piece.size[:2], small_size, self.taken[fixture])
            if at is None:
                return None
            gap = 0.5 * (max(small_size[:2]) + max(tall_size[:2])) + 0.02
            front = (round(at[0] + ux * gap, 3), round(at[1] + uy * gap, 3))
            hx, hy = tall_size[0] / 2, tall_size[1] / 2
            if (
                abs(front[0]) + hx > piece.size[0] / 2 - 0.02
                or abs(front[1]) + hy > piece.size[1] / 2 - 0.02
            ):
                continue
            rect = (
                front[0] - hx - 0.01,
                front[1] - hy - 0.01,
                front[0] + hx + 0.01,
                front[1] + hy + 0.01,
            )
            if any(overlap(rect, other) for other in self.taken[fixture]):
                continue
            self.reserve(fixture, at, small_size)
            self.reserve(fixture, front, tall_size)
            hidden = Item(self.new_id(small), small, small_size, fixture, at)
            cover = Item(self.new_id(tall), tall, tall_size, fixture, front)
            self.house.items += [hidden, cover]
            self.house.behind[hidden.id] = cover.id
            return hidden, cover
        return None
