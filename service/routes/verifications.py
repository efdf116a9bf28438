"""Coarse-stage verification: what waits for a verdict, and recording one."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query

from api_schema import CommandResult, VerdictIn, VerificationItem, VerificationList
from core.events import VerificationRequested
from core.verification import decide_verdict
from service.commands import run_command
from service.deps import ContainerDep, SceneDep, StatesDep, TrackId
from service.wire import event_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["verification"])


@router.get("/verifications", response_model=VerificationList)
def list_verifications(
    scene: SceneDep,
    container: ContainerDep,
    states: StatesDep,
    status: Annotated[
        Literal["pending", "all"], Query(description="`all` adds answered ones.")
    ] = "pending",
) -> VerificationList:
    """Tracks waiting for a verdict: candidate labels with their evidence and the frame to crop."""
    state = states.state(scene.id)
    requests = {
        stored.track_id: stored
        for stored in container.log.read(scene.id, event_type="verification_requested")
    }
    items = []
    for track_id, stored in sorted(requests.items(), key=lambda item: str(item[0])):
        track = state.tracks.get(str(track_id))
        request = stored.to_core()
        assert isinstance(request, VerificationRequested)
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
                candidates=dict(request.candidates),
                batch_votes=dict(request.batch_votes),
                best_frame=track.best_frame,
                requested_seq=stored.seq,
            )
        )
    return VerificationList(verifications=items)


@router.post("/tracks/{track_id}/verification", status_code=201, response_model=CommandResult)
def post_verdict(
    scene: SceneDep, track_id: TrackId, body: VerdictIn, container: ContainerDep
) -> CommandResult:
    """Record a verdict (evidence weight 3, existence +1.8 / -2.2): confirms or retires the track."""
    _events, appended = run_command(
        container,
        scene.id,
        lambda head: decide_verdict(
            head, track_id, body.verdict, body.label, body.source, body.frame_id
        ),
    )
    seqs = appended.seqs
    stored = [] if seqs is None else container.log.read(scene.id, after=seqs[0] - 1, up_to=seqs[1])
    return CommandResult(
        scene_id=scene.id,
        track_id=track_id,
        state=appended.state.tracks[track_id].lifecycle,
        events=[event_out(e) for e in stored],
    )
