"""Fixture tracks and states on hand-built maps, for the planner's tests."""

from __future__ import annotations

from dataclasses import replace
from typing import Unpack

from core.occupancy import OccupancyGrid
from core.state import SceneState, Track, TrackChanges


def fixture(
    track_id: str,
    center: tuple[float, float, float],
    extent: tuple[float, float, float],
    /,
    **changes: Unpack[TrackChanges],
) -> Track:
    """A confirmed table: seen 12 times at one place (evidence 12, p 0.99999), one class, a
    clear margin, pinned (u close to 0 unless `changes` say otherwise)."""
    track = Track(
        track_id=track_id,
        kind="fixture",
        lifecycle="confirmed",
        class_evidence={"table": 12.0},
        existence_logodds=4.0,
        center=center,
        extent=extent,
        recent_centers=(center, center),
        batches_observed=12,
        margin_sum=12 * 0.3,
        last_observed=100.0,
        pinned=True,
    )
    return track.evolved(**changes)


def scene(grid: OccupancyGrid, *tracks: Track, clock: float = 400.0) -> SceneState:
    """A state of these tracks on this map, its clock at `clock`."""
    return replace(
        SceneState(head_seq=10),
        tracks={t.track_id: t for t in tracks},
        occupancy=grid,
        clock=clock,
    )
