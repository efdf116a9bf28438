"""`python -m sim.robot --scene NAME_OR_ID`: the robot streams into a scene that exists."""

from __future__ import annotations

import pytest

import sim.robot as robot
from pbdag_client import Client
from service.app import create_app
from service.bootstrap import Container
from service.worker import Worker
from tests.clients import local_pbdag_client


def stream(client: Client, scene: str | None = None) -> str:
    """Two frames of the demo robot, into `scene` (an id or a name) or a new scene."""
    return robot.run_robot(
        "", frames=2, frames_per_batch=2, progress=False, client=client, scene=scene
    )


def test_the_robot_streams_into_the_scene_it_is_given_by_name_or_id(container: Container) -> None:
    with local_pbdag_client(create_app(container, run_worker=False)) as client:
        kitchen = client.create_scene("kitchen")
        assert stream(client, "kitchen") == kitchen.id
        assert stream(client, kitchen.id) == kitchen.id
        hall = stream(client, "hall")  # a name no scene has: created once, then reused
        assert stream(client, "hall") == hall != kitchen.id
        fresh = stream(client)  # without --scene, a new scene every run, as before
        assert fresh not in (kitchen.id, hall)
        assert sorted(scene.name for scene in client.scenes()) == ["hall", "kitchen", "sim-demo"]
        Worker(container).drain()
        assert client.scene(kitchen.id).head_seq > 0  # the batches went into the given scene
        client.create_scene("kitchen")  # a second scene of that name
        with pytest.raises(ValueError, match=r"2 scenes are named 'kitchen'.*pass one's id"):
            stream(client, "kitchen")
