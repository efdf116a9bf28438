"""The moves, transfers and the rest of a generated dynamic world's script: where each carried or
moved object goes, and the events timed from what the planning render shows."""

from __future__ import annotations

import math
import random

from sim.generator.events import Candidate, Scripter
from sim.generator.knobs import WorldKnobs
from sim.generator.layout import House, Item
from sim.generator.objects import ON, Shelver
from sim.generator.visibility import Sightings


def destinations(
    house: House, shelver: Shelver, plain: list[Item], rng: random.Random
) -> tuple[list[Item], list[Candidate], list[Candidate]]:
    """Destinations of transfers and moves, stood in for by planning objects ("ghosts") so the
    planning render can time when each place is seen."""
    fixtures = house.fixtures()
    ghosts: list[Item] = []
    transfers: list[Candidate] = []
    moves: list[Candidate] = []
    for item in plain[:8]:
        others = [p for p in fixtures if p.id != item.on and item.label in ON[p.label]]
        rng.shuffle(others)
        for target in others[:1]:
            spot = shelver.spot(target.id, item.size)
            if spot is not None:
                ghost = Item(f"ghost_{len(ghosts)}", item.label, item.size, target.id, spot)
                ghosts.append(ghost)
                transfers.append(Candidate(item.id, item.on, item.at, ghost.id, target.id, spot))
    for item in plain:
        if len(moves) >= 10:
            break
        # A spot 0.25 m or more away on the same top (a spot too close stays unused).
        for _ in range(3):
            spot = shelver.spot(item.on, item.size)
            if spot is not None and math.dist(spot, item.at) >= 0.25:
                ghost = Item(f"ghost_{len(ghosts)}", item.label, item.size, item.on, spot)
                ghosts.append(ghost)
                moves.append(Candidate(item.id, item.on, item.at, ghost.id, item.on, spot))
                break
    return ghosts, transfers, moves


def scripted_events(
    rng: random.Random,
    sights: Sightings,
    knobs: WorldKnobs,
    house: House,
    appear_pairs: list[tuple[Item, Item]],
    plain: list[Item],
    transfers: list[Candidate],
    moves: list[Candidate],
) -> tuple[Scripter, list[Item]]:
    """The scripted events, timed from what the planning render shows; the objects listed at
    the start (all but the one that appears)."""
    scripter = Scripter(rng, sights, knobs.frames)
    as_candidate = {i.id: Candidate(i.id, i.on, i.at) for i in house.items}
    appearing = scripter.appear_behind(
        [
            (as_candidate[small.id], small.label, small.size, cover.id)
            for small, cover in appear_pairs
        ]
    )
    listed = [i for i in house.items if i.id != appearing]
    hidden_first = [as_candidate[i] for i in house.behind if i in as_candidate]
    scripter.disappear_hidden(hidden_first + [as_candidate[i.id] for i in plain])
    by_label: dict[str, list[Item]] = {}
    for item in plain:
        by_label.setdefault(item.label, []).append(item)
    pairs = [
        (as_candidate[a.id], as_candidate[b.id])
        for group in by_label.values()
        for k, a in enumerate(group)
        for b in group[k + 1 :]
        if a.on != b.on and a.size == b.size
    ]
    scripter.swap(pairs)
    scripter.transfer(transfers, new_first=True)
    scripter.transfer(transfers, new_first=False)
    scripter.move(moves)
    scripter.leave_and_return([as_candidate[i.id] for i in plain])
    return scripter, listed
