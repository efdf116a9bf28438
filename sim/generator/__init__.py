"""Procedural worlds for the evaluation: houses nobody tuned on, with dev and test seed splits.

`generate_world(seed)` returns a scenario mapping (`sim.scenario.scenario_from_dict` reads it);
`generate_world_with_notes` also returns what the generator put in (hard events, visits,
occlusions); `python -m sim.generator --seed S` writes the YAML. See sim/scenarios/README.md.
"""

from sim.generator.knobs import (
    DEV_SEED_START,
    TEST_SEED_START,
    HardEvent,
    WorldKnobs,
    WorldNotes,
    active_knobs,
    split_seeds,
)
from sim.generator.world import GenerationError, generate_world, generate_world_with_notes

__all__ = [
    "DEV_SEED_START",
    "TEST_SEED_START",
    "GenerationError",
    "HardEvent",
    "WorldKnobs",
    "WorldNotes",
    "active_knobs",
    "generate_world",
    "generate_world_with_notes",
    "split_seeds",
]
