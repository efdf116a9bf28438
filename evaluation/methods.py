"""The methods compared on identical streams: PBD-AG, inspired baselines, alternative rules, ablations.

Each is the same `core.decide` loop with other parameters, other update rules (`core.rules`),
or a runner hook (periodic maintenance and a publication filter, periodic reset, freezing).
None of them changes the core's code. evaluation/README.md cites where each rule comes from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from core.params import FixtureParams, deep_merge
from core.profiles import EXTENDED, EXTENSIONS, PAPER, extension_named
from core.rules import UpdateRules
from evaluation.conceptgraphs import ConceptGraphsHooks
from evaluation.hooks import RunnerHooks
from pbdag_errors import Refused

# Publish on the first sighting: one batch and p_exist 0.73 after eta_o suffice.
IMMEDIATE = {"confirm_min_batches": 1, "confirm_min_p_exist": 0.5}
FOREVER = 1.0e12  # an identity memory that only forgets removed tracks
NO_SIZE_LIMIT = (0.0, 0.0, 0.0, 100.0, 100.0, 100.0)
# Fixtures published on first sight: no consensus gate, no absorption of residual clusters.
# Absorption cannot be switched off within the core's parameter ranges (fractions are at most 1);
# 1.0 absorbs only a residual lying wholly inside a matched fixture's expanded footprint. A
# second track of one fixture is not absorbed either (PBD-AG's `absorb_contained_tracks`).
UNVERIFIED_FIXTURES = {
    "confirm_min_batches": 1,
    "consensus_min_agreement": 0.0,
    "consensus_min_margin": 0.0,
    "residual_containment": 1.0,
    "absorb_contained_tracks": False,
}


OURS = EXTENDED.label  # the service's default profile: the paper plus our extensions
PAPERS = PAPER.label  # every rule as the paper writes it


class MethodUnavailable(Refused, RuntimeError):
    """A method whose update rule this core does not offer yet."""


@dataclass(frozen=True)
class Method:
    """One update rule on the shared loop."""

    name: str
    description: str  # two sentences: the rule it isolates, and the system it comes from
    params: dict[str, Any] = field(default_factory=dict)
    # Fields of core.rules.UpdateRules; a field this core lacks makes the method unavailable
    # (it is skipped with that reason) instead of silently running another rule.
    rule_flags: Mapping[str, Any] = field(default_factory=dict)
    reset_every_frames: int | None = None  # online remap: memory rebuilt from scratch
    freeze_after_fraction: float | None = None  # static-only: the first part, then nothing
    hooks: Callable[[], RunnerHooks] | None = None  # per-run maintenance and publication filter

    def unavailable_reason(self) -> str | None:
        """Why this core cannot run the method, None when it can."""
        known = {rule.name for rule in dataclasses.fields(UpdateRules)}
        missing = sorted(set(self.rule_flags) - known)
        if missing:
            return f"core.rules.UpdateRules has no field {', '.join(missing)} yet"
        return None

    @property
    def rules(self) -> UpdateRules:
        """The update rules, built from the flags (raises MethodUnavailable when it cannot)."""
        reason = self.unavailable_reason()
        if reason is not None:
            raise MethodUnavailable(f"{self.name}: {reason}")
        return UpdateRules(**self.rule_flags)

    @property
    def changes_the_loop(self) -> bool:
        """Whether the method needs the in-process loop (the HTTP API runs only parameters)."""
        return bool(
            self.rule_flags or self.hooks or self.reset_every_frames or self.freeze_after_fraction
        )


DYNAMIC_METHODS: tuple[Method, ...] = (
    Method(
        OURS,
        "The service's default profile: the paper's cross-batch confirmation, visibility-gated "
        "existence log-odds and persistent identities, plus every extension of core/profiles.py.",
    ),
    Method(
        PAPERS,
        "The paper's method as it writes it (core/profiles.py `paper`): every extension off, "
        "the log-odds unclamped, the fallback lending any identity of a unique class.",
        params=dict(PAPER.overrides),
    ),
    Method(
        "DynaMem-inspired",
        "Isolates DynaMem's update rule: objects are published on first sight and cleared as soon as "
        "depth shows free space where they were (a miss counts only when the measured depth at the "
        "box samples lies beyond the expected depth plus the margin). A voxel memory keeps no "
        "identity across a removal, and there is no unique-class recovery.",
        params={
            "lifecycle": {
                **IMMEDIATE,
                "remove_min_visible_misses": 1,
                "remove_at_most_p_exist": 0.99,
                "demote_below_p_exist": 0.0,
            },
            "association": {"unique_class_fallback": False},
        },
        rule_flags={"identity_memory_s": FOREVER, "miss_evidence": "free_space"},
    ),
    Method(
        "ConceptGraphs-inspired",
        "Isolates ConceptGraphs' mapping rules: detections merge into same-class nodes; a node is "
        "published once detected 3 times; every 10 frames same-class nodes whose boxes overlap by "
        "70 % with appearance cosine above 0.7 are merged, and nodes still below 3 detections "
        "after a period are dropped. The map is static: unseen nodes are never removed.",
        params={"lifecycle": IMMEDIATE, "association": {"unique_class_fallback": False}},
        rule_flags={"removal": False, "identity_memory_s": FOREVER},
        hooks=ConceptGraphsHooks,
    ),
    Method(
        "Last observation",
        "A memory that only replaces what it sees again: every detection is published at once, a "
        "node keeps the position, class and support of its latest matched observation, and a node "
        "not seen again stays where it was last seen (nothing is ever removed).",
        params={"lifecycle": IMMEDIATE, "association": {"unique_class_fallback": False}},
        rule_flags={"removal": False},
    ),
    Method(
        "Append-only",
        "PBD-AG without removal: evidence of absence is recorded but never acted upon. It isolates "
        "the append-only map of reconstruction systems.",
        rule_flags={"removal": False},
    ),
    Method(
        "Static-only",
        "The memory built during the first third of the run, frozen afterwards. It isolates a "
        "static scene graph built once (a pre-mapped baseline without deltas).",
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
        rule_flags={"visibility_gate": False},
    ),
    Method(
        "w/o persistent ID",
        "PBD-AG where a track unseen for more than a second, or removed, can no longer be matched, and "
        "the unique-class fallback is off. The component ablation of persistent identity.",
        params={"association": {"unique_class_fallback": False}},
        rule_flags={"identity_memory_s": 1.0},
    ),
)

FIXTURE_METHODS: tuple[Method, ...] = (
    Method(
        OURS,
        "Voxel class evidence with a margin test, DBSCAN, size limits, footprint association with "
        "residual absorption, and promotion after several batches with the consensus gate; with "
        "our merges of a second track inside a fixture and of two classes in one place.",
    ),
    Method(
        PAPERS,
        "The same without our extensions (core/profiles.py `paper`): strictly same-class "
        "association, no merge of a second track, the closest top as support parent.",
        params=dict(PAPER.overrides),
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
                # Footprint overlap only: coverage counts only when the proposal lies wholly
                # inside the expanded footprint (1.0, the top of the core's range).
                "min_expanded_coverage": 1.0,
                "default_size_limits": list(NO_SIZE_LIMIT),
                "size_limits": {
                    label: list(NO_SIZE_LIMIT) for label in FixtureParams().size_limits
                },
            },
            "lifecycle": IMMEDIATE,
        },
    ),
)


def _gate_methods() -> tuple[Method, ...]:
    """The visibility gate ablated twice: the paper's gate against none, and each condition we
    added against the paper's gate alone."""
    added = [
        Method(
            f"{PAPERS} + {name}",
            f"The paper's profile with one condition of ours added to its gate: "
            f"{extension_named(name).title}.",
            params=PAPER.plus(extension_named(name)),
        )
        for name in ("empty_place", "missed_detection")
    ]
    return (
        Method(
            f"{PAPERS} w/o visibility gate",
            "The paper's profile where every unmatched track inside the image and the range "
            "takes a miss: the paper's gate against none.",
            params=dict(PAPER.overrides),
            rule_flags={"visibility_gate": False},
        ),
        *added,
    )


ABLATION_METHODS: tuple[Method, ...] = (
    DYNAMIC_METHODS[0],
    *(
        Method(
            f"{OURS} - {extension.name}",
            f"Leave one out: the extended profile without {extension.title} (it exists for "
            f"{extension.case}).",
            params=EXTENDED.without(extension),
        )
        for extension in EXTENSIONS
    ),
    DYNAMIC_METHODS[1],
    *_gate_methods(),
)
"""The leave-one-out table of every extension, and the two readings of the gate ablation."""


def method_named(
    name: str, methods: tuple[Method, ...] = DYNAMIC_METHODS + FIXTURE_METHODS + ABLATION_METHODS
) -> Method:
    """Look a method up by its name (case-insensitive)."""
    for method in methods:
        if method.name.lower() == name.lower():
            return method
    raise KeyError(f"unknown method {name!r}; known: {', '.join(m.name for m in methods)}")


def with_params(methods: Sequence[Method], overrides: Mapping[str, Any]) -> list[Method]:
    """The methods on one parameter set other than core/params.py's defaults: `overrides` for
    every method, with each method's own settings (what makes it that method) on top."""
    return [
        dataclasses.replace(method, params=deep_merge(dict(overrides), method.params))
        for method in methods
    ]
