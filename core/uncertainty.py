"""Fixture uncertainty u_i = w . phi_i, equation (4) (section 3.4).

phi_i holds six terms, each increasing from 0 (certain) to 1, in the paper's order:
existence, class, parent, position, age, confirmation. The transforms are documented with their
constants in core/params.py (UncertaintyParams).

The existence term reads the state's log-odds, equation (3) exactly, wherever the clamp leaves
it; the clamp (`ExistenceParams.logodds_max`, 1.5, an extension) exists so that misses can
remove a long-seen object, and it pins every confirmed fixture at p = 0.82, which would make
4 p (1 - p) the constant .597. Pinned there, the term reads equation (3) summed over the
fixture's counters without the clamp (`evidence_logodds`). A fixture's parent term is 0 as long as it has no parent evidence (the
frontend gives fixtures none), so its weight (.10) is spent on a constant for fixtures.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from core.params import Params
from core.state import Track, logistic

TERMS = ("existence", "class", "parent", "position", "age", "confirmation")


@dataclass(frozen=True)
class Uncertainty:
    """u_i and its six terms phi_i."""

    value: float
    terms: dict[str, float]


def normalized_entropy(probabilities: Iterable[float], classes: int) -> float:
    """H(p) / log K, in [0, 1] (0 when K < 2)."""
    if classes < 2:
        return 0.0
    entropy = -sum(p * math.log(p) for p in probabilities if p > 0)
    return min(1.0, max(0.0, entropy / math.log(classes)))


def existence_term(p_exist: float) -> float:
    """Existence ambiguity 4 p (1 - p): 0 at p = 0 or 1, 1 at p = 0.5."""
    return 4.0 * p_exist * (1.0 - p_exist)


def evidence_logodds(fixture: Track, params: Params) -> float:
    """The fixture's existence log-odds without the clamp. Below the clamp's top the state's
    log-odds is equation (3) exactly, and is returned as it is (the paper's profile, whose
    log-odds are unclamped, always reads it). Pinned at the top, the clamp has dropped what lay
    above it, so equation (3) is summed over the fixture's counted evidence: the prior, eta_o per
    supporting batch, eta_c for a confirming verdict (eta_r off for a rejection), eta_m per
    visibility-admissible miss since its last positive batch (the counter restarts there; misses
    before it are not counted). Never below the state's log-odds: a fixture loaded from a
    baseline carries its log-odds and no batches."""
    e = params.existence
    if fixture.existence_logodds < e.logodds_max:
        return fixture.existence_logodds
    logodds = e.prior_logodds + e.eta_observed * fixture.batches_observed
    logodds -= e.eta_missed * fixture.visible_misses
    if fixture.verification == "confirmed":
        logodds += e.eta_confirmed
    elif fixture.verification == "rejected":
        logodds -= e.eta_rejected
    return max(logodds, fixture.existence_logodds)


def class_term(fixture: Track, params: Params) -> float:
    """share * H(p_cls) / log K + (1 - share) * clip(1 - mean margin / full margin, 0, 1)."""
    u = params.uncertainty
    probabilities = fixture.class_probabilities()
    classes = max(len(params.fixtures.taxonomy), len(probabilities))
    entropy = normalized_entropy(probabilities.values(), classes)
    batches = fixture.batches_observed
    margin = fixture.margin_sum / batches if batches > 0 else 0.0
    ambiguity = min(1.0, max(0.0, 1.0 - margin / u.class_margin_full))
    return u.class_entropy_share * entropy + (1.0 - u.class_entropy_share) * ambiguity


def parent_term(fixture: Track) -> float:
    """Normalized entropy of p_parent (0 with one candidate parent or none)."""
    probabilities = fixture.parent_probabilities()
    return normalized_entropy(probabilities.values(), len(probabilities))


def position_term(fixture: Track, params: Params) -> float:
    """sqrt(S_xx + S_yy) of the recent centers over the full spread, clipped (1 with < 2)."""
    if len(fixture.recent_centers) < 2:
        return 1.0
    covariance = np.cov(np.asarray(fixture.recent_centers, dtype=np.float64).T)
    spread = math.sqrt(max(float(covariance[0, 0] + covariance[1, 1]), 0.0))
    return min(1.0, spread / params.uncertainty.position_sigma_full_m)


def age_term(fixture: Track, clock: float | None, params: Params) -> float:
    """(scene clock - tau_i) / full age, clipped; 1 when never observed."""
    if fixture.last_observed is None:
        return 1.0
    now = fixture.last_observed if clock is None else clock
    return min(1.0, max(0.0, now - fixture.last_observed) / params.uncertainty.age_full_s)


def confirmation_term(fixture: Track, params: Params) -> float:
    """1 at the confirmation minimum of supporting batches, 0 at the full count; 0 if pinned."""
    if fixture.pinned:
        return 0.0
    low = params.fixtures.confirm_min_batches
    full = params.uncertainty.confirmation_batches_full
    span = max(full - low, 1)
    return min(1.0, max(0.0, (full - fixture.batches_observed) / span))


def fixture_uncertainty(fixture: Track, clock: float | None, params: Params) -> Uncertainty:
    """u_i of equation (4) with its terms (existence from the unclamped evidence)."""
    values = (
        existence_term(logistic(evidence_logodds(fixture, params))),
        class_term(fixture, params),
        parent_term(fixture),
        position_term(fixture, params),
        age_term(fixture, clock, params),
        confirmation_term(fixture, params),
    )
    terms = dict(zip(TERMS, values, strict=True))
    value = sum(w * phi for w, phi in zip(params.uncertainty.weights, values, strict=True))
    return Uncertainty(value, terms)
