"""Evidence: existence log-odds (equation (3)) and class evidence (section 3.3)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from core.params import AssociationParams, ExistenceParams


def update_existence(
    logodds: float,
    params: ExistenceParams,
    *,
    observed: bool = False,
    confirmed: bool = False,
    visible_miss: float = False,
    rejected: bool = False,
) -> float:
    """l_t = l_{t-1} + eta_o O + eta_c K - eta_m U V - eta_r R, clamped to the documented range.

    `visible_miss` is U_i^t * V_i(t): an unmatched track that is also visible. An unmatched track
    that is out of view or occluded is not a visible miss and leaves l unchanged. A weight above
    1 counts a clear view of an empty place for more than a glimpse (`clear_view_miss_weight`).
    """
    updated = (
        logodds
        + params.eta_observed * observed
        + params.eta_confirmed * confirmed
        - params.eta_missed * visible_miss
        - params.eta_rejected * rejected
    )
    return min(params.logodds_max, max(params.logodds_min, updated))


def class_distribution(
    label: str, scores: Mapping[str, float] | None, from_scores: bool = True
) -> dict[str, float]:
    """A detection's class evidence: its scores clipped at 0 and normalized, else its label.

    An ordinary observation adds unit evidence (section 3.3); spread over the classes the
    detector scored (ours, `fusion.class_evidence_from_scores`), so that a label flickering
    between confusable classes (cup/mug) builds one class belief instead of two tracks. With
    `from_scores` False it is the paper's: the unit goes to the label.
    """
    if scores and from_scores:
        positive = {name: max(float(value), 0.0) for name, value in scores.items()}
        positive[label] = positive.get(label, 0.0)
        total = sum(positive.values())
        if total > 0:
            return {name: value / total for name, value in sorted(positive.items()) if value > 0}
    return {label: 1.0}


def class_compatibility(belief: Mapping[str, float], observed: Mapping[str, float]) -> float:
    """How likely a track and a detection name the same class: sum_c p_track(c) q_det(c)."""
    return sum(p * observed.get(name, 0.0) for name, p in belief.items())


def classes_agree(
    belief: Mapping[str, float],
    label: str,
    observed: Mapping[str, float],
    params: AssociationParams,
) -> bool:
    """Class agreement of the association gate between a class belief and a detection (its
    `label` and its class evidence `observed`, `class_distribution` of it): ours, their soft
    compatibility reaches `min_class_compatibility`; the paper's (`soft_class_agreement`
    False), the detection's label is the belief's most likely class."""
    if params.soft_class_agreement:
        if params.min_class_compatibility > 0 and belief.keys().isdisjoint(observed):
            return False  # no class in common: the compatibility is 0 (each term p * 0)
        return class_compatibility(belief, observed) >= params.min_class_compatibility
    return most_supported(belief) == label


def add_support_evidence(
    previous: Mapping[str, float], parents: Sequence[str | None], weight: float
) -> dict[str, float]:
    """Support-parent evidence after one batch: `weight` for each sighting's parent (p_parent
    is this normalized)."""
    evidence = dict(previous)
    for parent in parents:
        if parent is not None:
            evidence[parent] = evidence.get(parent, 0.0) + weight
    return evidence


def most_supported(evidence: Mapping[str, float], current: str | None = None) -> str | None:
    """Most supported key; the current one keeps ties, then names decide."""
    if not evidence:
        return None
    best = max(evidence.values())
    if current is not None and evidence.get(current) == best:
        return current
    return min(key for key, weight in evidence.items() if weight == best)
