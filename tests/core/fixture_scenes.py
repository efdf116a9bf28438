"""Fixture scenes for core tests: the rendered room run batch by batch, and second fixture tracks
made from the table's own."""

from __future__ import annotations

from dataclasses import replace

from core.events import Event, FixtureAdded
from core.evolve import fold
from core.state import SceneState, Track
from tests.core.scenes import run_log

run = run_log


def fixtures_of(state: SceneState) -> list[Track]:
    return [t for t in state.tracks.values() if t.kind == "fixture"]


def with_twin_of_another_class(
    state: SceneState, events: list[Event], twin: str, label: str, shift: float
) -> SceneState:
    """The state with a second track of the table's size and top, labelled `label`, `shift`
    metres along x from the table (made from the table's own hypothesis and publication, with
    one supporting batch fewer)."""
    (table,) = [t for t in fixtures_of(state) if t.label == "table"]
    center = (table.center[0] + shift, table.center[1], table.center[2])
    copied: list[Event] = []
    for event in events:
        if event.track_id != table.track_id or event.type not in ("add", "confirm"):
            continue
        if isinstance(event, FixtureAdded):
            observation = replace(
                event.observations[0], label=label, center=center, extent=table.extent
            )
            event = replace(event, center=center, observations=(observation,))
        copied.append(replace(event, track_id=twin))
    twinned = fold(state, copied)
    twin_track = twinned.tracks[twin].evolved(
        class_evidence={label: 1.0},
        batches_observed=table.batches_observed - 1,
        center=center,
        extent=table.extent,
    )
    return replace(twinned, tracks={**twinned.tracks, twin: twin_track})


def with_second_table(state: SceneState, events: list[Event], twin: str) -> SceneState:
    """The state with a second table track: the first one's hypothesis and publication, made
    over again 0.3 m from its center and half its size (a part of the table seen first)."""
    (table,) = [t for t in fixtures_of(state) if t.label == "table"]
    shift = (table.center[0] + 0.3, table.center[1], table.center[2])
    copied: list[Event] = []
    for event in events:
        if event.track_id != table.track_id or event.type not in ("add", "confirm"):
            continue
        if isinstance(event, FixtureAdded):
            x, y, z = event.observations[0].extent
            half = (x / 2, y / 2, z / 2)
            observation = replace(event.observations[0], center=shift, extent=half)
            event = replace(event, center=shift, observations=(observation,))
        copied.append(replace(event, track_id=twin))
    return fold(state, copied)
