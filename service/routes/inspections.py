"""Inspection captures: record one, read the ledger, and the queue of fixtures to inspect."""

from __future__ import annotations

import uuid

from fastapi import APIRouter

from api_schema import (
    Inspection,
    InspectionIn,
    InspectionList,
    InspectionQueue,
    InspectionQueueItem,
)
from core.inspection import decide_inspection
from service.codec import decode_frames
from service.commands import run_command
from service.deps import ContainerDep, StatesDep
from service.store.event_log import StoredEvent

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["inspections"])


def inspection_out(event: StoredEvent) -> Inspection:
    """A ledger entry from its event."""
    return Inspection.model_validate({"seq": event.seq, **event.details})


@router.post("/inspections", status_code=201, response_model=Inspection)
def post_inspection(scene_id: str, body: InspectionIn, container: ContainerDep) -> Inspection:
    """Ground the primary view's objects on the fixture, attach them as its children, record the capture."""
    container.log.scene(scene_id)
    frames = decode_frames(body.frames)  # 422 naming the field; nothing is appended
    capture_id = body.capture_id or f"cap-{uuid.uuid4().hex[:12]}"
    _state, _events, seqs = run_command(
        container,
        scene_id,
        lambda head: decide_inspection(
            head, capture_id, body.fixture_id, frames, body.fixture_verified
        ),
    )
    assert seqs is not None
    return inspection_out(container.log.read(scene_id, after=seqs[1] - 1, up_to=seqs[1])[0])


@router.get("/inspections", response_model=InspectionList)
def list_inspections(scene_id: str, container: ContainerDep) -> InspectionList:
    """The capture ledger: every inspection with its frames, outcome and children."""
    container.log.scene(scene_id)
    return InspectionList(
        inspections=[
            inspection_out(e) for e in container.log.read(scene_id, event_type="inspection")
        ]
    )


@router.get("/inspection-queue", response_model=InspectionQueue)
def inspection_queue(scene_id: str, states: StatesDep) -> InspectionQueue:
    """Confirmed fixtures of the inspection taxonomy whose close-range inspection is unresolved."""
    state = states.state(scene_id)
    taxonomy = set(state.params.fixtures.inspection_taxonomy)
    return InspectionQueue(
        fixtures=[
            InspectionQueueItem(
                fixture_id=t.track_id,
                label=t.label,
                p_exist=t.p_exist,
                center=list(t.center),
                attempts=t.inspection_attempts,
            )
            for t in (state.tracks[i] for i in sorted(state.tracks))
            if t.kind == "fixture"
            and t.lifecycle == "confirmed"
            and t.label in taxonomy
            and t.inspection_status is None
        ]
    )
