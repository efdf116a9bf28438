"""Baselines as rule sets: the rule guard, and ConceptGraphs' count filter, merge and pruning."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pytest

from core.events import ObjectAdded, TrackRemoved
from core.params import Params
from core.rules import UpdateRules
from core.state import SceneState, Track
from core.values import Observation
from evaluation.conceptgraphs import ConceptGraphsHooks, contained_share
from evaluation.methods import (
    DYNAMIC_METHODS,
    FIXTURE_METHODS,
    Method,
    MethodUnavailable,
    method_named,
    with_params,
)

DIM = 4


def track(track_id: str, label: str, center: tuple[float, float, float], look: int = 0) -> Track:
    """A confirmed object track with a 10 cm box and a one-hot appearance."""
    appearance = tuple(1.0 if k == look else 0.0 for k in range(DIM))
    return Track(
        track_id=track_id,
        kind="object",
        lifecycle="confirmed",
        class_evidence={label: 1.0},
        existence_logodds=2.0,
        center=center,
        extent=(0.1, 0.1, 0.1),
        recent_centers=(center,),
        embedding_sum=appearance,
        embedding_count=1,
    )


def seen(track_id: str, times: int) -> ObjectAdded:
    """An event carrying `times` detections of a track (only the count matters to the hook)."""
    observation = Observation(
        frame_id="f", label="mug", score=0.9, center=(0, 0, 0), extent=(0.1, 0.1, 0.1),
        valid_pixels=100, parent=None,
    )  # fmt: skip
    return ObjectAdded(
        track_id=track_id,
        state="tentative",
        observations=(observation,) * times,
        embedding_sum=None,
        embedding_count=0,
        timestamp=0.0,
        existence_logodds=1.0,
        p_exist=0.73,
        batches_observed=1,
        parent_evidence={},
    )


def test_contained_share_is_the_inner_volume_inside_the_outer_box() -> None:
    a = track("a", "mug", (0.0, 0.0, 0.0))
    b = track("b", "mug", (0.05, 0.0, 0.0))  # half of each 10 cm box lies inside the other
    far = track("c", "mug", (1.0, 0.0, 0.0))
    assert contained_share(a, b) == pytest.approx(0.5)
    assert contained_share(a, far) == 0.0


def test_conceptgraphs_publishes_after_three_detections_merges_overlaps_and_prunes() -> None:
    # a: 4 detections; b: 2, 2 cm from a (80 % of b inside a) and alike -> merged into a;
    # c: a cup where a is (another class) -> kept; e: a mug where a is but unlike it
    # (cosine 0) -> kept; d: one detection at frame 1, never again -> pruned at the
    # maintenance after the first full period without a detection.
    tracks = {
        "a": track("a", "mug", (0.0, 0.0, 0.0)),
        "b": track("b", "mug", (0.02, 0.0, 0.0)),
        "c": track("c", "cup", (0.0, 0.0, 0.0), look=1),
        "d": track("d", "mug", (2.0, 0.0, 0.0)),
        "e": track("e", "mug", (0.0, 0.01, 0.0), look=2),
    }
    state = SceneState(tracks=tracks)
    hooks = ConceptGraphsHooks()
    first = [seen("a", 4), seen("b", 2), seen("c", 3), seen("d", 1), seen("e", 3)]
    assert hooks.after_batch(state, first, last_frame=1) == []  # no maintenance before frame 10
    assert [hooks.publishable(tracks[k]) for k in "abcde"] == [True, False, True, False, True]
    merged = hooks.after_batch(state, [], last_frame=11)
    assert [(e.track_id, type(e)) for e in merged] == [("b", TrackRemoved)]
    assert hooks.detections["a"] == 6  # b's detections count for a
    assert hooks.after_batch(state, [], last_frame=15) == []  # not yet another period
    pruned = hooks.after_batch(state, [], last_frame=21)
    assert "d" in {e.track_id for e in pruned} and "a" not in {e.track_id for e in pruned}


def test_a_method_needing_a_rule_the_core_lacks_is_unavailable_not_replaced() -> None:
    future = Method("Future", "needs a rule", rule_flags={"no_such_rule": True})
    assert "no_such_rule" in (future.unavailable_reason() or "")
    with pytest.raises(MethodUnavailable):
        _ = future.rules
    gated = Method("Gate off", "an ablation", rule_flags={"visibility_gate": False})
    assert gated.unavailable_reason() is None
    assert gated.rules == UpdateRules(visibility_gate=False)
    assert method_named("pbd-ag (extended)").rules == UpdateRules()
    assert not method_named("PBD-AG (extended)").changes_the_loop and gated.changes_the_loop


def leaves(
    tree: Mapping[str, Any], sections: Mapping[str, Any], prefix: str = ""
) -> dict[str, Any]:
    """A parameter tree as dotted paths to values; a key is a section when it is one in
    `sections` (the default tree)."""
    found: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, Mapping) and isinstance(sections.get(key), Mapping):
            found |= leaves(value, sections[key], f"{prefix}{key}.")
        else:
            found[f"{prefix}{key}"] = value
    return found


def test_every_method_s_parameters_change_what_they_name_and_nothing_else() -> None:
    """Each override is valid for this core, reaches the parameters as written, and differs
    from the default (an override equal to it would claim a difference the row does not have)."""
    defaults = Params().to_dict()
    default = leaves(defaults, defaults)
    for method in DYNAMIC_METHODS + FIXTURE_METHODS:
        named = leaves(method.params, defaults)
        resolved = leaves(Params.from_dict(method.params).to_dict(), defaults)
        assert {path: resolved[path] for path in named} == named, method.name
        changed = {path for path, value in resolved.items() if value != default[path]}
        assert changed == set(named), method.name
    assert any(method.params for method in DYNAMIC_METHODS + FIXTURE_METHODS)


def test_dynamem_asks_the_core_for_free_space_misses() -> None:
    dynamem = method_named("DynaMem-inspired")
    assert dynamem.rule_flags["miss_evidence"] == "free_space"
    names = [method.name for method in DYNAMIC_METHODS]
    assert names[:4] == [
        "PBD-AG (extended)",
        "PBD-AG (paper)",
        "DynaMem-inspired",
        "ConceptGraphs-inspired",
    ]


def test_one_parameter_set_for_every_method_with_each_methods_own_settings_on_top() -> None:
    overrides = {
        "visibility": {"min_expected_image_fraction": 0.002},
        "lifecycle": {"confirm_min_batches": 3, "remove_min_visible_misses": 4},
    }
    methods = {m.name: m for m in with_params(DYNAMIC_METHODS, overrides)}
    ours = Params.from_dict(methods["PBD-AG (extended)"].params)
    assert ours.visibility.min_expected_image_fraction == 0.002
    assert ours.lifecycle.confirm_min_batches == 3
    dynamem = Params.from_dict(methods["DynaMem-inspired"].params)
    # The override reaches the baseline, but what makes DynaMem DynaMem stays.
    assert dynamem.visibility.min_expected_image_fraction == 0.002
    assert dynamem.lifecycle.confirm_min_batches == 1
    assert dynamem.lifecycle.remove_min_visible_misses == 1
    # The catalogue itself is untouched.
    assert method_named("PBD-AG (extended)").params == {}
