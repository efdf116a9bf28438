"""Cached coarse-stage verification (section 3.2): a verdict on a pending fixture hypothesis."""

from __future__ import annotations

from typing import Literal

from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.events import Event, TrackConfirmed, TrackRemoved, TrackVerified
from core.params import Params
from core.state import SceneState, logistic
from core.transitions import fixture_verdict_logodds


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
    lifecycle = track.lifecycle
    details = {
        "verdict": verdict,
        "label": label,
        "source": source,
        "frame_id": frame_id,
        "existence_logodds": logodds,
        "p_exist": p_exist,
    }
    events: list[Event] = [TrackVerified(track_id, lifecycle, frame_id, details)]
    if not confirm:
        # Rejected hypotheses are retired: removed, and never re-acquired.
        events.append(
            TrackRemoved(
                track_id,
                "removed",
                frame_id,
                {"p_exist": p_exist, "reason": "verification_rejected"},
            )
        )
        return events
    enough_batches = track.batches_observed >= (
        params.fixtures.confirm_min_batches
        if track.kind == "fixture"
        else params.lifecycle.confirm_min_batches
    )
    if (
        lifecycle != "confirmed"
        and enough_batches
        and p_exist >= params.lifecycle.confirm_min_p_exist
    ):
        events.append(
            TrackConfirmed(
                track_id,
                "confirmed",
                frame_id,
                {
                    "p_exist": p_exist,
                    "center": list(track.center),
                    "batches_observed": track.batches_observed,
                    "reason": "verification",
                },
            )
        )
    return events
