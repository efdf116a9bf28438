"""Existence log-odds, equation (3) (section 3.3, "Visibility-gated existence")."""

from __future__ import annotations

from core.params import ExistenceParams


def update_existence(
    logodds: float,
    params: ExistenceParams,
    *,
    observed: bool = False,
    confirmed: bool = False,
    visible_miss: bool = False,
    rejected: bool = False,
) -> float:
    """l_t = l_{t-1} + eta_o O + eta_c K - eta_m U V - eta_r R, clamped to the documented range.

    `visible_miss` is U_i^t * V_i(t): an unmatched track that is also visible. An unmatched track
    that is out of view or occluded is not a visible miss and leaves l unchanged.
    """
    updated = (
        logodds
        + params.eta_observed * observed
        + params.eta_confirmed * confirmed
        - params.eta_missed * visible_miss
        - params.eta_rejected * rejected
    )
    return min(params.logodds_max, max(params.logodds_min, updated))
