"""Cached coarse-stage verification (section 3.2): a verdict on a pending fixture hypothesis."""

from __future__ import annotations

from typing import Literal

from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.events import Event, TrackRemoved, TrackVerified
from core.lifecycle import should_confirm
from core.params import Params
from core.state import SceneState, logistic
from core.transitions import confirmed, fixture_verdict_logodds


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
    confirm = verdict == "confirm"
    logodds = fixture_verdict_logodds(track, confirm, params)
    p_exist = logistic(logodds)
    events: list[Event] = [
        TrackVerified(
            track_id=track_id,
            state=track.lifecycle,
            frame_id=frame_id,
            verdict=verdict,
            label=label,
            source=source,
            verdict_frame=frame_id,
            existence_logodds=logodds,
            p_exist=p_exist,
        )
    ]
    if not confirm:
        # Rejected hypotheses are retired: removed, and never re-acquired.
        events.append(
            TrackRemoved(
                track_id=track_id,
                state="removed",
                frame_id=frame_id,
                p_exist=p_exist,
                reason="verification_rejected",
            )
        )
        return events
    if should_confirm(track.kind, track.lifecycle, p_exist, track.batches_observed, params):
        events.append(
            confirmed(
                track_id,
                frame_id,
                p_exist,
                track.center,
                track.batches_observed,
                reason="verification",
            )
        )
    return events
