"""Cached coarse-stage verification (section 3.2): a verdict on a pending fixture hypothesis."""

from __future__ import annotations

from typing import Literal

from core.emit import decision_events
from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.events import Event
from core.existence import verdict_update
from core.lifecycle import verdict_decision
from core.params import Params
from core.state import SceneState


def decide_verdict(
    state: SceneState,
    track_id: str,
    verdict: Literal["confirm", "reject"],
    label: str | None,
    source: str,
    frame_id: str | None,
    params: Params | None = None,
) -> list[Event]:
    """`verify` (evidence weight 3, existence +1.8 or -2.2), then `confirm`, or retirement."""
    params = params or state.params
    track = state.tracks.get(track_id)
    if track is None:
        raise UnknownTrack(f"track {track_id!r} does not exist", "track_id")
    if track.verification in ("confirmed", "rejected") and (
        frame_id is None or frame_id == track.verdict_frame
    ):
        raise StateConflict(
            f"track {track_id!r} already has a verdict ({track.verification}); "
            "a second one must name a new observation (frame_id)",
            "frame_id",
        )
    if track.lifecycle == "removed" and track.verification == "rejected":
        raise StateConflict(f"track {track_id!r} was retired by a rejection", "track_id")
    label = label or track.label
    if track.kind == "fixture" and label not in params.fixtures.taxonomy:
        raise InvalidCommand(f"label {label!r} is not in the scene's fixture taxonomy", "label")
    update = verdict_update(track, verdict == "confirm", label, source, frame_id, params)
    return decision_events([verdict_decision(track, update, params)], params)
