"""The methods compared on identical streams: PBD-AG, inspired baselines, alternative rules, ablations.

Each is the same `core.decide` loop with other parameters, other update rules, or another
runner hook (publication, periodic reset, freezing). None of them changes the core's code.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from core.params import FixtureParams
from core.rules import PAPER_RULES, UpdateRules

# Publish on the first sighting: one batch and p_exist 0.73 after eta_o suffice.
IMMEDIATE = {"confirm_min_batches": 1, "confirm_min_p_exist": 0.5}
FOREVER = 1.0e12  # an identity memory that only forgets removed tracks
NO_SIZE_LIMIT = (0.0, 0.0, 0.0, 100.0, 100.0, 100.0)
# Fixtures published on first sight: no consensus gate, no absorption of residual clusters.
UNVERIFIED_FIXTURES = {
    "confirm_min_batches": 1,
    "consensus_min_agreement": 0.0,
    "consensus_min_margin": 0.0,
    "residual_containment": 2.0,
}


@dataclass(frozen=True)
class Method:
    """One update rule on the shared loop."""

    name: str
    description: str  # two sentences: the rule it isolates, and the system it comes from
    params: dict[str, Any] = field(default_factory=dict)
    rules: UpdateRules = PAPER_RULES
    publish_last_batch_only: bool = False  # the graph is what the last batch saw
    reset_every_frames: int | None = None  # online remap: memory rebuilt from scratch
    freeze_after_fraction: float | None = (
        None  # static-only: the first part of the run, then nothing
    )


DYNAMIC_METHODS: tuple[Method, ...] = (
    Method(
        "PBD-AG",
        "The paper's method: cross-batch confirmation, visibility-gated existence log-odds and "
        "persistent identities that survive removal. Every component is on.",
    ),
    Method(
        "DynaMem-inspired",
        "Isolates DynaMem's update rule: objects are published on first sight and cleared as soon as "
        "depth shows free space where they were. Identities are not kept across a removal (a voxel "
        "memory has no object identity), and there is no unique-class recovery.",
        params={
            "lifecycle": {
                **IMMEDIATE,
                "remove_min_visible_misses": 1,
                "remove_at_most_p_exist": 0.99,
                "demote_below_p_exist": 0.0,
            },
            "association": {"unique_class_fallback": False},
        },
        rules=UpdateRules(identity_memory_s=FOREVER),
    ),
    Method(
        "ConceptGraphs-inspired",
        "Isolates ConceptGraphs' incremental merging: each detection is merged into the nearest "
        "same-class node with similar appearance or becomes a new node, published at once. The map is "
        "built for a static scene, so nothing is ever removed and a far move leaves a stale node.",
        params={"lifecycle": IMMEDIATE, "association": {"unique_class_fallback": False}},
        rules=UpdateRules(removal=False),
    ),
    Method(
        "Last observation",
        "The graph is exactly what the last batch saw, with identities carried by association. "
        "It isolates memory-less state estimation, the rule of frame-by-frame perception stacks.",
        params={"lifecycle": IMMEDIATE},
        publish_last_batch_only=True,
    ),
    Method(
        "Append-only",
        "PBD-AG without removal: evidence of absence is recorded but never acted upon. It isolates "
        "the append-only map of reconstruction systems.",
        rules=UpdateRules(removal=False),
    ),
    Method(
        "Static-only",
        "The memory built during the first loop of the run, frozen afterwards. It isolates a static "
        "scene graph built once (a pre-mapped baseline without deltas).",
        freeze_after_fraction=1 / 3,
    ),
    Method(
        "Online remap",
        "PBD-AG's rules, but the memory is rebuilt from scratch every 60 frames, so identities do not "
        "survive a remap. It isolates periodic global reconstruction.",
        reset_every_frames=60,
    ),
    Method(
        "w/o visibility gate",
        "PBD-AG where every unmatched track inside the image and the range takes a miss, occluded or "
        "not. The component ablation of the geometric visibility gate.",
        rules=UpdateRules(visibility_gate=False),
    ),
    Method(
        "w/o persistent ID",
        "PBD-AG where a track unseen for more than a second, or removed, can no longer be matched, and "
        "the unique-class fallback is off. The component ablation of persistent identity.",
        params={"association": {"unique_class_fallback": False}},
        rules=UpdateRules(identity_memory_s=1.0),
    ),
)

FIXTURE_METHODS: tuple[Method, ...] = (
    Method(
        "PBD-AG",
        "Voxel class evidence with a margin test, DBSCAN, size limits, footprint association with "
        "residual absorption, and promotion after several batches with the consensus gate.",
    ),
    Method(
        "DynaMem-adapted",
        "The same proposals, but published on first sight without the consensus gate and without "
        "absorbing residual clusters. It isolates immediate, unverified coarse updates.",
        params={
            "fixtures": UNVERIFIED_FIXTURES,
            "lifecycle": IMMEDIATE,
        },
    ),
    Method(
        "ConceptGraphs-adapted",
        "The same proposals, merged by footprint overlap only, without size plausibility, absorption "
        "or consensus. It isolates geometric merging of open-vocabulary segments.",
        params={
            "fixtures": {
                **UNVERIFIED_FIXTURES,
                "min_expanded_coverage": 2.0,
                "default_size_limits": list(NO_SIZE_LIMIT),
                "size_limits": {
                    label: list(NO_SIZE_LIMIT) for label in FixtureParams().size_limits
                },
            },
            "lifecycle": IMMEDIATE,
        },
    ),
)


def method_named(
    name: str, methods: tuple[Method, ...] = DYNAMIC_METHODS + FIXTURE_METHODS
) -> Method:
    """Look a method up by its name (case-insensitive)."""
    for method in methods:
        if method.name.lower() == name.lower():
            return method
    raise KeyError(f"unknown method {name!r}; known: {', '.join(m.name for m in methods)}")
