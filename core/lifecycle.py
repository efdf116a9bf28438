"""Lifecycle transition rules (section 3.3, "Lifecycle transitions and audit events")."""

from __future__ import annotations

import math

from core.params import LifecycleParams, Params
from core.values import LifecycleState, TrackKind, Vec3


def should_confirm(
    kind: TrackKind,
    lifecycle: LifecycleState,
    p_exist: float,
    batches_observed: int,
    params: Params,
) -> bool:
    """Publication needs cross-batch confirmation and p_exist >= 0.72.

    The one confirmation rule of objects, fixtures and verdicts: fixtures need support from
    more distinct batches (section 3.2), objects from `confirm_min_batches` (section 3.3).
    """
    min_batches = (
        params.fixtures.confirm_min_batches
        if kind == "fixture"
        else params.lifecycle.confirm_min_batches
    )
    return (
        lifecycle in ("tentative", "demoted")
        and batches_observed >= min_batches
        and p_exist >= params.lifecycle.confirm_min_p_exist
    )


def should_demote(lifecycle: LifecycleState, p_exist: float, params: LifecycleParams) -> bool:
    """A published node is demoted when p_exist < 0.30."""
    return lifecycle == "confirmed" and p_exist < params.demote_below_p_exist


def should_remove(
    lifecycle: LifecycleState,
    p_exist: float,
    visible_misses: int,
    pinned: bool,
    params: LifecycleParams,
) -> bool:
    """Removal needs p_exist <= 0.12 after at least three visibility-admissible misses."""
    return (
        lifecycle != "removed"
        and not pinned
        and visible_misses >= params.remove_min_visible_misses
        and p_exist <= params.remove_at_most_p_exist
    )


def moved_distance(published: Vec3 | None, center: Vec3) -> float:
    """Distance from the last published position (0 when never published)."""
    return 0.0 if published is None else math.dist(published, center)


def should_move(published: Vec3 | None, center: Vec3, params: LifecycleParams) -> bool:
    """Motion of at least 0.35 m from the last published position emits `move`."""
    return published is not None and moved_distance(published, center) >= params.move_min_distance_m
