"""The two parameter sets of the method: the paper's (`paper`) and ours (`extended`).

`paper` is every rule of sections 3.2-3.4 as the paper writes it. `extended` is the paper plus
the rules we added, each a named switch of `core/params.py` (`EXTENSIONS`: what it is, the
section it departs from, and the overrides that restore the paper's rule). `extended` is the
parameter defaults, and so what a scene gets unless it asks for another profile; `paper` is
those defaults with every extension switched off. The update rules (`core.rules`) are the
paper's in both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from core.params import MAX_LOGODDS, Params, deep_merge

# A hypothesis never seen again stays in the association pool for 31 years: never retires.
NEVER_S = 1.0e9


@dataclass(frozen=True)
class Extension:
    """One rule beside the paper's, and the parameter values that switch it off."""

    name: str  # an identifier: its leave-one-out row is `PBD-AG (extended) - NAME`
    title: str  # what it does, in a few words
    section: str  # the paper's section it departs from
    paper: Mapping[str, Any]  # nested overrides that restore the paper's rule
    case: str  # the case it exists for

    def on(self) -> dict[str, Any]:
        """The overrides that switch it on: the defaults of `core/params.py` at its paths."""
        defaults = Params().to_dict()
        switched: dict[str, Any] = {}
        for path, _ in _leaves(self.paper):
            switched = deep_merge(switched, _nested(path, _value_at(defaults, path)))
        return switched

    def is_on(self, params: Params) -> bool:
        """Whether `params` run this rule (any of its switches away from the paper's value)."""
        tree = params.to_dict()
        return any(_value_at(tree, path) != value for path, value in _leaves(self.paper))


def _leaves(
    tree: Mapping[str, Any], prefix: tuple[str, ...] = ()
) -> list[tuple[tuple[str, ...], Any]]:
    leaves = []
    for key, value in tree.items():
        if isinstance(value, Mapping):
            leaves.extend(_leaves(value, (*prefix, key)))
        else:
            leaves.append(((*prefix, key), value))
    return leaves


def _nested(path: tuple[str, ...], value: Any) -> dict[str, Any]:
    tree: Any = value
    for key in reversed(path):
        tree = {key: tree}
    result: dict[str, Any] = tree
    return result


def _value_at(tree: Mapping[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = tree
    for key in path:
        value = value[key]
    return value


EXTENSIONS: tuple[Extension, ...] = (
    Extension(
        "fragment_rule",
        "over-segmented pieces set aside",
        "3.3 type-specific association",
        {"association": {"fragment_max_growth": 0.0}},
        "a detector reporting one object as two masks",
    ),
    Extension(
        "object_merge",
        "two tracks of one object merged",
        "3.3 type-specific association",
        {"association": {"absorb_contained_tracks": False}},
        "an object split into two hypotheses at its first sighting",
    ),
    Extension(
        "fixture_merge",
        "a second track inside a fixture merged",
        "3.2 association of fixture proposals",
        {"fixtures": {"absorb_contained_tracks": False}},
        "a fixture seen in parts first (half a desk)",
    ),
    Extension(
        "same_place_merge",
        "fixtures of two classes in one place merged",
        "3.2 association of fixture proposals",
        {"fixtures": {"same_place_min_iou": 1.0}},
        "a desk the segmenter calls a table in some views",
    ),
    Extension(
        "fixture_class_margin",
        "near-best fixture classes agree",
        "3.2 association of fixture proposals (same-class)",
        {"fixtures": {"compatible_class_margin": 0.0}},
        "a cluster scoring 0.50 desk and 0.47 table on a table track",
    ),
    Extension(
        "deferred_reidentification",
        "a hypothesis takes a missing identity back",
        "3.3 type-specific association (unique-class fallback)",
        {"association": {"reidentify_hypotheses": False}},
        "a carried object seen at its new place before its old place is seen empty",
    ),
    Extension(
        "fallback_absence",
        "the fallback lends only established absences",
        "3.3 type-specific association (unique-class fallback)",
        {"association": {"fallback_requires_absence": False}},
        "an object still in place, merely undetected, whose identity would go elsewhere",
    ),
    Extension(
        "fallback_ranking",
        "the fallback ranks candidates by appearance",
        "3.3 type-specific association (unique-class fallback)",
        {"association": {"fallback_ranks_by_appearance": False}},
        "a carried mug among other mugs",
    ),
    Extension(
        "claimed_hypotheses",
        "a hypothesis that may be a known object waits to be published",
        "3.3 lifecycle transitions (confirm)",
        {"association": {"claimed_hold_max_batches": 0}},
        "a carried object seen at its new place before its old place is seen empty",
    ),
    Extension(
        "clear_view_misses",
        "a clear view of an empty place counts for more than a glimpse",
        "3.3 visibility-gated existence (equation (3))",
        {"existence": {"clear_view_miss_weight": 1.0}},
        "an object taken away, its place seen clearly in one pass of the route",
    ),
    Extension(
        "identity_handover",
        "a published younger track hands a missing identity back",
        "3.3 type-specific association (unique-class fallback)",
        {"association": {"reidentify_published": False}},
        "a carried object seen at its new place first, and published there, before its old "
        "place is seen empty",
    ),
    Extension(
        "unrefuted_rivals",
        "unrefuted tracks of the class compete in the fallback",
        "3.3 type-specific association (unique-class fallback)",
        {"association": {"unrefuted_rivals": False}},
        "two mugs: one taken away, the other carried far while its own track still stands",
    ),
    Extension(
        "soft_class_agreement",
        "class agreement from the detector's scores",
        "3.3 type-specific association (class agreement)",
        {"association": {"soft_class_agreement": False}},
        "a label flickering between confusable classes (cup/mug)",
    ),
    Extension(
        "score_class_evidence",
        "class evidence spread over the detector's scores",
        "3.3 persistent state fusion (unit evidence)",
        {"fusion": {"class_evidence_from_scores": False}},
        "the same flicker, building one class belief",
    ),
    Extension(
        "logodds_clamp",
        "existence log-odds clamped to [-4, 1.5]",
        "3.3 visibility-gated existence, equation (3)",
        {"existence": {"logodds_min": -MAX_LOGODDS, "logodds_max": MAX_LOGODDS}},
        "an object seen hundreds of times, then gone",
    ),
    Extension(
        "empty_place",
        "a miss needs the depth to show the place empty",
        "3.3 visibility-gated existence (V_i)",
        {"visibility": {"miss_requires_empty_center": False}},
        "an object in plain view that the detector missed",
    ),
    Extension(
        "missed_detection",
        "a miss needs a detectable projection",
        "3.3 visibility-gated existence (V_i)",
        {"visibility": {"min_expected_image_fraction": 0.0, "min_in_image_share": 0.0}},
        "a sliver at the image border, a grazing or a far view",
    ),
    Extension(
        "place_corroboration",
        "a match away from the place adds no evidence",
        "3.3 visibility-gated existence (O_i)",
        {"lifecycle": {"corroborate_at_place": False}},
        "a same-label false positive near a vanished object",
    ),
    Extension(
        "stale_retirement",
        "unseen hypotheses retire after 60 s",
        "3.3 lifecycle transitions",
        {"lifecycle": {"retire_unseen_hypothesis_s": NEVER_S}},
        "glimpses and false positives piling up in the association pool",
    ),
    Extension(
        "published_parent",
        "a published fixture wins as support parent",
        "3.2 geometrically assigned parent",
        {"fixtures": {"published_parent_first": False}},
        "a second, unconfirmed hypothesis of a counter under its objects",
    ),
    Extension(
        "top_voxel_band",
        "an object may rest anywhere in its fixture's top voxel",
        "3.2 geometrically assigned parent",
        {"fixtures": {"support_top_band_m": 0.0}},
        "keys on a desk whose top voxel reaches 0.09 m above the desk",
    ),
    Extension(
        "primary_view",
        "the sweep's view that grounds the most is the primary",
        "3.4 fixture-centered inspection (one contract-valid primary view)",
        {"inspection": {"primary_view": "first"}},
        "a mug the detector misses in the sweep's first view and reports in the next",
    ),
    Extension(
        "sweep_class_votes",
        "the sweep's views vote on each object's label",
        "3.4 fixture-centered inspection (alternates not fused)",
        {"inspection": {"sweep_class_votes": False}},
        "a mug labelled cup in one view of the sweep and mug in the other two",
    ),
)


def _paper_overrides() -> dict[str, Any]:
    merged: dict[str, Any] = {}
    for extension in EXTENSIONS:
        merged = deep_merge(merged, extension.paper)
    return merged


@dataclass(frozen=True)
class Profile:
    """A named parameter set: overrides of `core/params.py`'s defaults."""

    name: str
    label: str  # the row name in the evaluation's tables
    description: str
    overrides: Mapping[str, Any] = field(default_factory=dict)

    @property
    def params(self) -> Params:
        return Params.from_dict(self.overrides)

    def without(self, extension: Extension) -> dict[str, Any]:
        """This profile's overrides with one extension switched off."""
        return deep_merge(dict(self.overrides), extension.paper)

    def plus(self, extension: Extension) -> dict[str, Any]:
        """This profile's overrides with one extension switched on."""
        return deep_merge(dict(self.overrides), extension.on())


PAPER = Profile(
    "paper",
    "PBD-AG (paper)",
    "Every rule as the paper writes it: no extension of core/params.py is on.",
    _paper_overrides(),
)
EXTENDED = Profile(
    "extended",
    "PBD-AG (extended)",
    "The paper's rules plus every extension of core/params.py (the parameter defaults).",
)
PROFILES: dict[str, Profile] = {profile.name: profile for profile in (PAPER, EXTENDED)}
DEFAULT_PROFILE = EXTENDED


def extension_named(name: str) -> Extension:
    """An extension by its name (KeyError lists the known ones)."""
    for extension in EXTENSIONS:
        if extension.name == name:
            return extension
    raise KeyError(f"unknown extension {name!r}; known: {', '.join(e.name for e in EXTENSIONS)}")
