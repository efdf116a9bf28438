"""The occupancy map A_t, and the plan: what to inspect next, from where, and why (section 3.4)."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request
from starlette.responses import Response

from api_schema import Occupancy, PlanIn, PlanOut
from codec.occupancy import occupancy_out, occupancy_png
from core.events import Event
from core.planner import Plan, decide_plan, plan
from core.state import SceneState
from core.values import ViewPose
from service.commands import run_command
from service.deps import AsOf, ContainerDep, SceneDep, StatesDep
from service.wire import plan_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["plan"])

PNG = "image/png"


def wants_png(request: Request, format: str | None) -> bool:
    """`?format=png`, or an Accept header that asks for PNG and not for JSON."""
    if format is not None:
        return format == "png"
    accept = request.headers.get("accept", "")
    return PNG in accept and "application/json" not in accept


@router.get(
    "/occupancy",
    response_model=Occupancy,
    responses={200: {"content": {PNG: {}}, "description": "The map as JSON or as a PNG."}},
)
def get_occupancy(
    scene: SceneDep,
    states: StatesDep,
    request: Request,
    as_of: AsOf,
    format: Annotated[
        Literal["json", "png"] | None,
        Query(description="`png` for an 8-bit grey image (default: by the Accept header)."),
    ] = None,
) -> Occupancy | Response:
    """The occupancy map at `as_of` (default now): its known window run-length encoded, with
    its frontiers; or a PNG (north up; unknown 205, free 254, occupied 0), whose origin and
    resolution are in the X-Map-Origin and X-Map-Resolution headers."""
    state = states.state(scene.id, as_of)
    if wants_png(request, format):
        body, origin = occupancy_png(state)
        headers = {
            "X-Map-Origin": f"{origin[0]:.6f},{origin[1]:.6f}",
            "X-Map-Resolution": f"{state.params.occupancy.resolution_m:g}",
            "X-Scene-Seq": str(state.head_seq),
        }
        return Response(body, media_type=PNG, headers=headers)
    return occupancy_out(scene.id, state)


@router.post("/plan", response_model=PlanOut)
def post_plan(scene: SceneDep, body: PlanIn, container: ContainerDep) -> PlanOut:
    """Decide on the head: `inspect` (a fixture, its view, u_i and J with their terms),
    `explore` (a frontier) or `done`. A new lock is appended as `inspection_targeted`."""
    pose = body.robot_pose
    robot = ViewPose(x=pose.x, y=pose.y, yaw=pose.yaw)
    decided: list[Plan] = []

    def decide(head: SceneState) -> list[Event]:
        plan_now, events = decide_plan(head, robot)
        decided.append(plan_now)  # decided again when the head moved meanwhile: keep the last
        return events

    _events, appended = run_command(container, scene.id, decide)
    event_seq = appended.seqs[1] if appended.seqs is not None else None
    return plan_out(scene.id, decided[-1], event_seq)


@router.get("/plan", response_model=PlanOut)
def preview_plan(
    scene: SceneDep,
    states: StatesDep,
    as_of: AsOf,
    x: Annotated[float, Query(ge=-200, le=200, allow_inf_nan=False, description="Metres.")],
    y: Annotated[float, Query(ge=-200, le=200, allow_inf_nan=False, description="Metres.")],
    yaw: Annotated[float, Query(ge=-10, le=10, allow_inf_nan=False, description="Radians.")] = 0.0,
) -> PlanOut:
    """The plan the robot at (x, y, yaw) would get at `as_of` (default now), without locking."""
    state = states.state(scene.id, as_of)
    return plan_out(scene.id, plan(state, ViewPose(x=x, y=y, yaw=yaw)), None)
