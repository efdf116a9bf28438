"""A simulated robot: walks a scenario (the demo's by default) and posts its batches to the HTTP API.

The batches are the stream's (`sim.stream`), the same the evaluation reads: this module only
speaks HTTP.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import httpx
from tqdm import tqdm

from api_schema import BatchIn, BatchStatus
from pbdag_client import Client, scenes_called
from sim import DEMO_SCENARIO
from sim.scenario import load_scenario
from sim.stream import iter_frames, iter_wire_batches

CONNECT_ATTEMPTS = 6  # with doubling from 0.2 s: about 6 s for the service to come up
FIRST_BACKOFF_SECONDS = 0.2

T = TypeVar("T")


def _with_retries(send: Callable[[], T], retry_on: tuple[type[Exception], ...]) -> T:
    """Call `send`, retrying with doubling backoff while the service is unreachable."""
    backoff = FIRST_BACKOFF_SECONDS
    for attempt in range(CONNECT_ATTEMPTS):
        try:
            return send()
        except retry_on:
            if attempt == CONNECT_ATTEMPTS - 1:
                raise
            time.sleep(backoff)
            backoff *= 2
    raise AssertionError("unreachable")  # the loop either returns or re-raises


def create_scene(client: Client, scene_name: str) -> str:
    """POST /v1/scenes and return the new scene's id."""
    # Only connection failures are retried: the request never reached the service, so a
    # retry cannot create a second scene.
    scene = _with_retries(
        lambda: client.create_scene(scene_name),
        retry_on=(httpx.ConnectError, httpx.ConnectTimeout),
    )
    return scene.id


def scene_for(client: Client, scene: str) -> str:
    """The id of the scene whose id or name is `scene`, created (named so) when none is."""
    called = scenes_called(
        _with_retries(client.scenes, retry_on=(httpx.ConnectError, httpx.ConnectTimeout)), scene
    )
    if len(called) > 1:
        ids = ", ".join(entry.id for entry in called)
        raise ValueError(f"{len(called)} scenes are named {scene!r} ({ids}); pass one's id")
    return called[0].id if called else create_scene(client, scene)


def post_batch(client: Client, scene_id: str, batch: BatchIn) -> BatchStatus:
    """POST one batch; any transport error is retried since batch_id makes the call idempotent."""
    return _with_retries(
        lambda: client.post_batch(scene_id, batch), retry_on=(httpx.TransportError,)
    )


def run_robot(
    base_url: str,
    *,
    scenario_path: str | Path = DEMO_SCENARIO,
    scene_name: str = "sim-demo",
    frames: int | None = None,
    frames_per_batch: int = 2,
    seed: int = 7,
    pace_seconds: float = 0.0,
    progress: bool = True,
    client: Client | None = None,
    token: str | None = None,
    scene: str | None = None,
) -> str:
    """Create a scene named `scene_name` (or, given `scene`, the scene of that id or name,
    created when none is), stream the scenario into it batch by batch, and return its id.

    `frames` shortens (or stretches) the scenario with its story intact (`load_scenario`).
    Without a `client`, one on `base_url` (with `token`) is opened and closed here.
    """
    if frames_per_batch < 1:
        raise ValueError("frames_per_batch must be at least 1")
    scenario = load_scenario(scenario_path, frames=frames)
    own_client = client is None
    http = client if client is not None else Client(base_url, token, timeout=30.0)
    try:
        scene_id = create_scene(http, scene_name) if scene is None else scene_for(http, scene)
        n_batches = -(-scenario.frames // frames_per_batch)
        batches = iter_wire_batches(scenario, seed, iter_frames(scenario, seed), frames_per_batch)
        progress_bar = tqdm(
            total=scenario.frames,
            desc=f"scene {scene_id}",
            unit="frame",
            file=sys.stderr,
            disable=not progress,
        )
        with progress_bar:
            for batch_index, (_, batch) in enumerate(batches):
                post_batch(http, scene_id, BatchIn.model_validate(batch))
                progress_bar.set_postfix(batch=f"{batch_index + 1}/{n_batches}", refresh=False)
                progress_bar.update(len(batch["frames"]))
                if pace_seconds > 0:
                    time.sleep(pace_seconds)
        return scene_id
    finally:
        if own_client:
            http.close()


def main(argv: list[str] | None = None) -> None:
    """Command line: python -m sim.robot --url http://localhost:8000."""
    parser = argparse.ArgumentParser(description="Stream a simulated robot run into PBD-AG.")
    parser.add_argument("--url", default="http://127.0.0.1:8000", help="service base URL")
    parser.add_argument(
        "--scenario", type=Path, default=DEMO_SCENARIO, help="scenario file (default: the demo)"
    )
    parser.add_argument("--frames", type=int, default=None, help="shorten the scenario to N frames")
    parser.add_argument("--frames-per-batch", type=int, default=2)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--pace", type=float, default=0.0, help="seconds to wait between batches")
    parser.add_argument("--name", default="sim-demo", help="the new scene's name")
    parser.add_argument(
        "--scene",
        default=None,
        help="stream into this scene (its id or name; created when none is) instead of a new one",
    )
    parser.add_argument(
        "--token",
        default=os.environ.get("PBDAG_TOKEN"),
        help="bearer token with the write scope (default: $PBDAG_TOKEN)",
    )
    args = parser.parse_args(argv)
    with Client(args.url, args.token, timeout=30.0) as client:
        try:
            scene_id = stream_from_arguments(args, client)
        except ValueError as error:  # two scenes of the name given, a batch size under 1
            parser.exit(2, f"sim.robot: {error}\n")
    print(scene_id)


def stream_from_arguments(args: argparse.Namespace, client: Client) -> str:
    """`run_robot` with the command line's choices."""
    return run_robot(
        args.url,
        scenario_path=args.scenario,
        scene_name=args.name,
        frames=args.frames,
        frames_per_batch=args.frames_per_batch,
        seed=args.seed,
        pace_seconds=args.pace,
        client=client,
        scene=args.scene,
    )


if __name__ == "__main__":
    main()
