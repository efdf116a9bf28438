"""Equation (3) and the class and support evidence of core/belief.py, against values computed
by hand from the paper's increments (eta_o, eta_c, eta_m, eta_r) = (1.0, 1.8, 0.70, 2.20) and
the clamp [-4.0, 1.5] of core/params.py."""

from __future__ import annotations

import math

import pytest

from core.belief import (
    add_support_evidence,
    class_compatibility,
    class_distribution,
    most_supported,
    update_existence,
)
from core.params import ExistenceParams
from core.state import logistic

ETA = ExistenceParams()


def test_the_paper_s_increments_are_the_defaults() -> None:
    assert (ETA.eta_observed, ETA.eta_confirmed, ETA.eta_missed, ETA.eta_rejected) == (
        1.0,
        1.8,
        0.70,
        2.20,
    )
    assert (ETA.prior_logodds, ETA.logodds_min, ETA.logodds_max) == (0.0, -4.0, 1.5)


def test_one_ordinary_observation_adds_eta_o() -> None:
    # l = 0 + 1.0 * 1 = 1.0; p = 1 / (1 + e^-1) = 0.7310585786300049, just past 0.72.
    logodds = update_existence(0.0, ETA, observed=True)
    assert logodds == 1.0
    assert logistic(logodds) == pytest.approx(0.7310585786300049, abs=1e-15)


def test_a_second_observation_is_clamped_at_the_top() -> None:
    # l = 1.0 + 1.0 = 2.0, clamped to 1.5 (p = 1 / (1 + e^-1.5) = 0.8175744761936437).
    logodds = update_existence(1.0, ETA, observed=True)
    assert logodds == 1.5
    assert logistic(logodds) == pytest.approx(0.8175744761936437, abs=1e-15)


def test_a_cached_confirmation_adds_eta_c_and_a_rejection_subtracts_eta_r() -> None:
    # From -1.0: -1.0 + 1.8 = 0.8. From 0.0: 0.0 - 2.2 = -2.2. From -3.0: -5.2, clamped to -4.0.
    assert update_existence(-1.0, ETA, confirmed=True) == pytest.approx(0.8, abs=1e-12)
    assert update_existence(0.0, ETA, rejected=True) == pytest.approx(-2.2, abs=1e-12)
    assert update_existence(-3.0, ETA, rejected=True) == -4.0


def test_misses_from_the_top_demote_after_four_and_reach_removal_after_five() -> None:
    # Each visible miss subtracts 0.70 from 1.5: 0.8, 0.1, -0.6, -1.3, -2.0.
    # p after each: 0.6900, 0.5250, 0.3543, 0.2142, 0.1192. Demotion needs p < 0.30 (the 4th),
    # removal p <= 0.12 (the 5th; three misses at least, which it has).
    expected = [0.8, 0.1, -0.6, -1.3, -2.0]
    probabilities = [0.6899744811276125, 0.52497918747894, 0.35434369377420455]
    probabilities += [0.21416501695744142, 0.11920292202211757]
    logodds = 1.5
    for want, p in zip(expected, probabilities, strict=True):
        logodds = update_existence(logodds, ETA, visible_miss=True)
        assert logodds == pytest.approx(want, abs=1e-12)
        assert logistic(logodds) == pytest.approx(p, abs=1e-12)
    assert logistic(-1.3) < 0.30 <= logistic(-0.6)
    assert logistic(-2.0) <= 0.12 < logistic(-1.3)


def test_every_term_at_once_and_none_at_all() -> None:
    # 0.2 + 1.0 + 1.8 - 0.70 - 2.20 = 0.1; an unmatched track out of view (no term) keeps 0.3.
    both = update_existence(
        0.2, ETA, observed=True, confirmed=True, visible_miss=True, rejected=True
    )
    assert both == pytest.approx(0.1, abs=1e-12)
    assert update_existence(0.3, ETA) == 0.3


def test_the_clamp_holds_at_the_bottom_for_misses() -> None:
    # -3.5 - 0.7 = -4.2, clamped to -4.0 (p = 0.01798620996209156).
    logodds = update_existence(-3.5, ETA, visible_miss=True)
    assert logodds == -4.0
    assert math.isclose(logistic(logodds), 0.01798620996209156, abs_tol=1e-15)


def test_class_distribution_spreads_unit_evidence_over_the_scored_classes() -> None:
    # Scores clipped at 0: cup 0.6, mug 0.3, bowl 0 -> total 0.9: cup 2/3, mug 1/3 (bowl out).
    evidence = class_distribution("cup", {"cup": 0.6, "mug": 0.3, "bowl": -0.1})
    assert list(evidence) == ["cup", "mug"]
    assert evidence["cup"] == pytest.approx(2 / 3, abs=1e-12)
    assert evidence["mug"] == pytest.approx(1 / 3, abs=1e-12)
    assert sum(evidence.values()) == pytest.approx(1.0, abs=1e-12)


def test_class_distribution_falls_back_to_the_label() -> None:
    assert class_distribution("mug", None) == {"mug": 1.0}
    assert class_distribution("mug", {}) == {"mug": 1.0}
    # Nothing positive (every score clipped to 0): the label alone.
    assert class_distribution("mug", {"mug": 0.0, "cup": -0.2}) == {"mug": 1.0}


def test_class_compatibility_is_the_inner_product_of_the_two_beliefs() -> None:
    # 0.5 * 2/3 + 0.5 * 1/3 = 0.5; disjoint classes: 0.
    assert class_compatibility(
        {"cup": 0.5, "mug": 0.5}, {"cup": 2 / 3, "mug": 1 / 3}
    ) == pytest.approx(0.5, abs=1e-12)
    assert class_compatibility({"cup": 1.0}, {"mug": 1.0}) == 0.0
    assert class_compatibility({"cup": 0.75, "mug": 0.25}, {"cup": 1.0}) == 0.75


def test_support_evidence_adds_the_weight_per_sighting_and_copies() -> None:
    # t1: 1.0 + 1.0 = 2.0; t2: 0 + 1.0; None (on nothing known) adds nothing.
    before = {"t1": 1.0}
    after = add_support_evidence(before, ["t1", None, "t2"], 1.0)
    assert after == {"t1": 2.0, "t2": 1.0}
    assert before == {"t1": 1.0}


def test_the_most_supported_key_keeps_the_current_one_on_ties() -> None:
    assert most_supported({}) is None
    assert most_supported({"b": 2.0, "a": 2.0}) == "a"  # ties: by name
    assert most_supported({"b": 2.0, "a": 2.0}, "b") == "b"  # ... unless one is current
    assert most_supported({"a": 1.0, "b": 2.0}, "a") == "b"
