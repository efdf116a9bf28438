"""Coarse-stage verification: what waits for a verdict, and recording one."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query

from api_schema import CommandResult, VerdictIn, VerificationItem, VerificationList
from core.verification import decide_verdict
from service.commands import run_command
from service.deps import ContainerDep, StatesDep
from service.routes.events import event_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["verification"])


@router.get("/verifications", response_model=VerificationList)
def list_verifications(
    scene_id: str,
    container: ContainerDep,
    states: StatesDep,
    status: Annotated[
        Literal["pending", "all"], Query(description="`all` adds answered ones.")
    ] = "pending",
) -> VerificationList:
    """Tracks waiting for a verdict: candidate labels with their evidence and the frame to crop."""
    state = states.state(scene_id)
    requests = {
        e.track_id: e for e in container.log.read(scene_id, event_type="verification_requested")
    }
    items = []
    for track_id, request in sorted(requests.items()):
        track = state.tracks.get(str(track_id))
        if track is None or (
            status == "pending"
            and (track.verification != "pending" or track.lifecycle == "removed")
        ):
            continue
        items.append(
            VerificationItem(
                track_id=track.track_id,
                label=track.label,
                state=track.lifecycle,
                verification=track.verification,
                candidates=request.details.get("candidates", {}),
                batch_votes=request.details.get("batch_votes", {}),
                best_frame=track.best_frame,
                requested_seq=request.seq,
            )
        )
    return VerificationList(verifications=items)


@router.post("/tracks/{track_id}/verification", status_code=201, response_model=CommandResult)
def post_verdict(
    scene_id: str, track_id: str, body: VerdictIn, container: ContainerDep
) -> CommandResult:
    """Record a verdict (evidence weight 3, existence +1.8 / -2.2): confirms or retires the track."""
    state, _events, seqs = run_command(
        container,
        scene_id,
        lambda head: decide_verdict(
            head, track_id, body.verdict, body.label, body.source, body.frame_id
        ),
    )
    appended = (
        [] if seqs is None else container.log.read(scene_id, after=seqs[0] - 1, up_to=seqs[1])
    )
    return CommandResult(
        scene_id=scene_id,
        track_id=track_id,
        state=state.tracks[track_id].lifecycle,
        events=[event_out(e) for e in appended],
    )
