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
from codec.observations import decode_frames
from core.events import InspectionRecorded
from core.inspection import decide_inspection
from core.planner import queue_status, unresolved_fixtures
from core.uncertainty import fixture_uncertainty
from core.values import ViewPose
from service.commands import run_command
from service.deps import ContainerDep, SceneDep, StatesDep
from service.wire import inspection_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["inspections"])


@router.post("/inspections", status_code=201, response_model=Inspection)
def post_inspection(scene: SceneDep, body: InspectionIn, container: ContainerDep) -> Inspection:
    """Ground the primary view's objects on the fixture, attach them as its children, record the capture."""
    frames = decode_frames(body.frames)  # 422 naming the field; nothing is appended
    capture_id = body.capture_id or f"cap-{uuid.uuid4().hex[:12]}"
    view = None if body.view is None else ViewPose(x=body.view.x, y=body.view.y, yaw=body.view.yaw)
    events, appended = run_command(
        container,
        scene.id,
        lambda head: decide_inspection(
            head, capture_id, body.fixture_id, frames, body.fixture_verified, view=view
        ),
    )
    record = events[-1]
    assert isinstance(record, InspectionRecorded) and appended.seqs is not None
    return inspection_out(appended.seqs[1], record)


@router.get("/inspections", response_model=InspectionList)
def list_inspections(scene: SceneDep, container: ContainerDep) -> InspectionList:
    """The capture ledger: every inspection with its frames, outcome and children."""
    ledger = []
    for stored in container.log.read(scene.id, event_type="inspection"):
        event = stored.to_core()
        assert isinstance(event, InspectionRecorded)
        ledger.append(inspection_out(stored.seq, event))
    return InspectionList(inspections=ledger)


@router.get("/inspection-queue", response_model=InspectionQueue)
def inspection_queue(scene: SceneDep, states: StatesDep) -> InspectionQueue:
    """Confirmed fixtures of the inspection taxonomy whose close-range inspection is unresolved,
    most uncertain first (u_i, equation (4)); Q_t is those `queued`."""
    state = states.state(scene.id)
    items = []
    for fixture in unresolved_fixtures(state):
        u = fixture_uncertainty(fixture, state.clock, state.params)
        items.append(
            InspectionQueueItem(
                fixture_id=fixture.track_id,
                label=fixture.label,
                p_exist=fixture.p_exist,
                center=list(fixture.center),
                attempts=fixture.inspection_attempts,
                status=queue_status(state, fixture.track_id),
                uncertainty=u.value,
            )
        )
    items.sort(key=lambda item: (-item.uncertainty, item.fixture_id))
    return InspectionQueue(fixtures=items)
