"""The event script of a generated world, timed from what the route shows when.

Each hard case of the evaluation gets one event (or pair): a carried object seen at its new
place before its old place is seen empty and the opposite order, a disappearance while hidden,
a move within its support, an appearance behind a taller object, two objects of one class
swapped, and an object that leaves and comes back.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

import numpy as np

from pbdag_errors import Refused
from sim.generator.knobs import HardEvent
from sim.generator.visibility import HIDDEN_PIXELS, Sightings

EventEntry = dict[str, object]


class Unscriptable(Refused):
    """No frame of the route fits an event: the generator draws the world again."""


@dataclass(frozen=True)
class Candidate:
    """An object an event may change, and (for moves and transfers) the spot it may go to."""

    object: str
    on: str
    at: tuple[float, float]
    ghost: str | None = None  # the planning object standing at the destination
    to: str | None = None
    to_at: tuple[float, float] | None = None


def _placed(frame: int, kind: str, object_id: str, where: Candidate) -> EventEntry:
    """An event that puts `object_id` where `where` stands (its fixture and spot)."""
    return {"frame": frame, "type": kind, "object": object_id, "on": where.on, "at": list(where.at)}


MIN_SIGHTINGS = 3  # an event object is seen this often before its change, and its result after


def _often(seen: np.ndarray, start: int, stop: int | None = None) -> bool:
    """Whether `seen` holds on at least MIN_SIGHTINGS frames of [start, stop)."""
    return int(seen[max(start, 0) : stop].sum()) >= MIN_SIGHTINGS


def _after(seen: np.ndarray, frame: int, stop: int | None = None) -> int | None:
    """The first frame after `frame` (and before `stop`) where `seen` holds."""
    hits = np.flatnonzero(seen[frame + 1 : stop])
    return None if len(hits) == 0 else frame + 1 + int(hits[0])


class Scripter:
    """Picks frames (and objects among candidates) for each hard event."""

    def __init__(self, rng: random.Random, sights: Sightings, frames: int) -> None:
        self.rng, self.sights, self.frames = rng, sights, frames
        self.window = list(range(int(0.12 * frames), int(0.8 * frames)))
        self.used: set[str] = set()
        self.events: list[EventEntry] = []
        self.hard: list[HardEvent] = []

    def _frames(self) -> list[int]:
        frames = list(self.window)
        self.rng.shuffle(frames)
        return frames

    def _free(self, candidates: list[Candidate]) -> list[Candidate]:
        return [c for c in candidates if c.object not in self.used]

    def _add(self, kind: str, entries: list[EventEntry], detail: str) -> None:
        self.events += entries
        objects = tuple(str(entry["object"]) for entry in entries)
        self.used.update(objects)
        frames = tuple(int(str(entry["frame"])) for entry in entries)
        self.hard.append(HardEvent(kind, objects, frames, detail))

    def transfer(self, candidates: list[Candidate], new_first: bool) -> None:
        """A carried object whose new place is seen before (or after) its old place."""
        for cand in self._free(candidates):
            assert cand.ghost is not None and cand.to is not None and cand.to_at is not None
            seen_old, seen_new = self.sights.seen(cand.object), self.sights.seen(cand.ghost)
            for frame in self._frames():
                if seen_old[frame] or seen_new[frame]:  # carried while neither place is in view
                    continue
                if not (_often(seen_old, 0, frame) and _often(seen_new, frame + 1)):
                    continue
                new, old = _after(seen_new, frame), _after(seen_old, frame)
                if new is None or old is None:
                    continue
                if (new + 3 <= old) if new_first else (old + 3 <= new):
                    entry: EventEntry = {
                        "frame": frame,
                        "type": "transfer",
                        "object": cand.object,
                        "on": cand.to,
                        "at": list(cand.to_at),
                    }
                    order = "new place first" if new_first else "old place first"
                    self._add(
                        "transfer_new_place_first" if new_first else "transfer_old_place_first",
                        [entry],
                        f"{order}: new place seen at {new}, old place at {old}",
                    )
                    return
        raise Unscriptable("transfer " + ("new place first" if new_first else "old place first"))

    def disappear_hidden(self, candidates: list[Candidate]) -> None:
        """A disappearance while the object is in view but hidden (else out of view)."""
        for hidden_only in (True, False):
            for cand in self._free(candidates):
                pixels, shown = self.sights.pixels[cand.object], self.sights.in_view[cand.object]
                seen = self.sights.seen(cand.object)
                for frame in self._frames():
                    hidden = bool(shown[frame]) and pixels[frame] < HIDDEN_PIXELS
                    if not (_often(seen, 0, frame) and _often(seen, frame + 1)):
                        continue
                    if hidden if hidden_only else not seen[frame]:
                        entry: EventEntry = {
                            "frame": frame,
                            "type": "disappear",
                            "object": cand.object,
                        }
                        detail = "in view, hidden" if hidden else "out of view"
                        self._add("disappear_while_hidden", [entry], detail)
                        return
        raise Unscriptable("disappearance while hidden")

    def move(self, candidates: list[Candidate]) -> None:
        """A move within the support, unseen when it happens, its new spot seen later."""
        for cand in self._free(candidates):
            assert cand.ghost is not None and cand.to_at is not None
            seen_old, seen_new = self.sights.seen(cand.object), self.sights.seen(cand.ghost)
            for frame in self._frames():
                if seen_old[frame] or seen_new[frame]:
                    continue
                if not (_often(seen_old, 0, frame) and _often(seen_new, frame + 1)):
                    continue
                entry: EventEntry = {
                    "frame": frame,
                    "type": "move",
                    "object": cand.object,
                    "at": list(cand.to_at),
                }
                self._add("move_within_support", [entry], f"on {cand.on}")
                return
        raise Unscriptable("move within a support")

    def appear_behind(
        self, candidates: list[tuple[Candidate, str, tuple[float, float, float], str]]
    ) -> str:
        """A new object put down behind a taller one while the robot is elsewhere (its id)."""
        for cand, label, size, cover in candidates:
            seen = self.sights.seen(cand.object)
            for frame in self._frames():
                if seen[frame] or not _often(seen, frame + 1):
                    continue
                entry: EventEntry = {
                    "frame": frame,
                    "type": "appear",
                    "object": cand.object,
                    "label": label,
                    "size": list(size),
                    "on": cand.on,
                    "at": list(cand.at),
                }
                self._add("appear_behind_occluder", [entry], f"behind {cover}")
                return cand.object
        raise Unscriptable("appearance behind an occluder")

    def swap(self, pairs: list[tuple[Candidate, Candidate]]) -> None:
        """Two objects of one class trade places in one frame (two transfers)."""
        for first, second in pairs:
            if first.object in self.used or second.object in self.used:
                continue
            seen_a, seen_b = self.sights.seen(first.object), self.sights.seen(second.object)
            for frame in self._frames():
                if seen_a[frame] or seen_b[frame]:
                    continue
                # Each is known before, and its new place (the other's old one) is seen after.
                if not (_often(seen_a, 0, frame) and _often(seen_b, 0, frame)):
                    continue
                if not (_often(seen_a, frame + 1) and _often(seen_b, frame + 1)):
                    continue
                entries: list[EventEntry] = [
                    _placed(frame, "transfer", first.object, second),
                    _placed(frame, "transfer", second.object, first),
                ]
                self._add("swap_same_class", entries, f"{first.on} <-> {second.on}")
                return
        raise Unscriptable("swap of two objects of one class")

    def leave_and_return(self, candidates: list[Candidate]) -> None:
        """An object taken away unseen, its empty place seen, then put back unseen."""
        last = int(0.92 * self.frames)
        for cand in self._free(candidates):
            seen = self.sights.seen(cand.object)
            for leave in self._frames():
                if seen[leave] or not _often(seen, 0, leave):
                    continue
                for back in range(leave + 30, last):
                    if seen[back] or _after(seen, leave, back) is None:
                        continue
                    if not _often(seen, back + 1):
                        continue
                    entries: list[EventEntry] = [
                        {"frame": leave, "type": "disappear", "object": cand.object},
                        _placed(back, "appear", cand.object, cand),
                    ]
                    self._add("leave_and_return", entries, f"away {back - leave} frames")
                    return
        raise Unscriptable("an object leaving and coming back")
