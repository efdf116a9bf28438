"""The newcomer's demo: the service on its SQLite default, fed live by the simulated robot.

    python -m sim.demo_service [--port 8000] [--frames 120] [--pace 0.15] [--exit]

Starts `pbdag serve` in this process (API + worker), lets the simulated robot stream the demo
scenario (sim/scenarios/demo.yaml) into a new scene, prints the graph and where to look, then
keeps serving until Ctrl-C (or exits with --exit). When the port is taken by another program,
it says so and serves on a free port instead, printing that URL.
"""

from __future__ import annotations

import argparse
import logging
import socket
import threading
import time

import uvicorn

from pbdag_client import Client, PbdagError
from service.app import create_app
from service.bootstrap import build_container
from service.settings import Settings
from sim.robot import run_robot

HOST = "127.0.0.1"


def listen(preferred: int) -> tuple[socket.socket, str | None]:
    """A socket bound on loopback to `preferred` (0: any free port), or to a free port when
    another program holds it, with a note saying so. The server is handed the bound socket,
    so no other program can take the port in between."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    # As uvicorn does: a port left in TIME_WAIT by an earlier run is free; one that another
    # socket listens on is not.
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((HOST, preferred))
        return sock, None
    except OSError as error:
        sock.bind((HOST, 0))
        port = sock.getsockname()[1]
        reason = error.strerror or str(error)
        return sock, f"Port {preferred} is busy ({reason}): serving on port {port} instead."


def wait_until_processed(client: Client, scene_id: str, timeout: float = 300.0) -> None:
    """Block until no batch is queued, running or waiting for a retry."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        counts = client.health().batches
        if counts.get("queued", 0) + counts.get("running", 0) + counts.get("failed", 0) == 0:
            return
        time.sleep(0.2)
    raise TimeoutError(f"scene {scene_id}: batches still pending after {timeout:.0f} s")


def print_summary(client: Client, base_url: str, scene_id: str) -> None:
    """Fixtures with the objects on them, removals and their reasons, verdicts waited for, a baseline."""
    scene = client.scene(scene_id)
    graph = client.graph(scene_id, include="all")
    print(f"\nScene {scene_id}: {scene.head_seq} events in the log.")
    print(
        f"{'track':<12} {'kind':<8} {'label':<8} {'state':<10} {'p_exist':>7}  {'on':<12} center [m]"
    )
    ordered = sorted(graph.nodes, key=lambda n: (n.kind != "fixture", n.parent or "", n.id))
    for node in ordered:
        center = ", ".join(f"{v:5.2f}" for v in node.center)
        note = " (waits for a verdict)" if node.verification == "pending" else ""
        print(
            f"{node.id:<12} {node.kind:<8} {node.label:<8} {node.state:<10} {node.p_exist:7.3f}  "
            f"{node.parent or '-':<12} ({center}){note}"
        )
    for node in graph.nodes:
        if node.state == "removed":
            print(f"why: {client.explain(scene_id, node.id).summary}")
    for item in client.verifications(scene_id):
        candidates = ", ".join(f"{label} {score:.2f}" for label, score in item.candidates.items())
        print(f"verification pending: {item.track_id} ({candidates}); crop frame {item.best_frame}")
    try:
        package = client.freeze_baseline(scene_id)
    except PbdagError as error:
        print(f"no baseline frozen: {error.detail}")
    else:
        fixtures = ", ".join(f"{f['track_id']} {f['label']}" for f in package.package["fixtures"])
        print(
            f"baseline v{package.version} frozen at seq {package.seq}: {fixtures}; sha256 {package.sha256[:16]}..."
        )
    print("\nWhere to look:")
    print(f"  viewer          {base_url}/viewer?scene={scene_id}")
    print(f"  API docs        {base_url}/docs")
    print(f"  graph now       {base_url}/v1/scenes/{scene_id}/graph")
    print(f"  graph at seq 40 {base_url}/v1/scenes/{scene_id}/graph?as_of=40")
    print(f"  event log       {base_url}/v1/scenes/{scene_id}/events?limit=50")
    print(f"  verifications   {base_url}/v1/scenes/{scene_id}/verifications")
    print(f"  baselines       {base_url}/v1/scenes/{scene_id}/baselines")
    print(f"  to inspect      {base_url}/v1/scenes/{scene_id}/inspection-queue")


def main(argv: list[str] | None = None) -> None:
    """Run the demo."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--frames", type=int, default=None, help="shorten the demo to N frames (it has 120)"
    )
    parser.add_argument("--frames-per-batch", type=int, default=2)
    parser.add_argument(
        "--pace", type=float, default=0.15, help="seconds between batches, to watch it live"
    )
    parser.add_argument(
        "--exit", action="store_true", help="stop the service once the run is processed"
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    # The demo's robot and your browser talk to its own server over loopback: no token needed.
    settings = Settings(allow_anonymous_local=True)
    sock, busy = listen(args.port)
    port = int(sock.getsockname()[1])
    base_url = f"http://{HOST}:{port}"
    server = uvicorn.Server(
        uvicorn.Config(
            create_app(build_container(settings), run_worker=True),
            host=HOST,
            port=port,
            log_level="warning",
        )
    )
    thread = threading.Thread(
        target=server.run, kwargs={"sockets": [sock]}, name="pbdag-api", daemon=True
    )
    thread.start()
    while not server.started:
        if not thread.is_alive():
            raise SystemExit(f"the service did not start on {base_url}")
        time.sleep(0.05)
    if busy is not None:
        print(busy)
    print(f"PBD-AG is serving on {base_url} (SQLite at {settings.resolved_database_url()}).")
    print(
        f"Open {base_url}/viewer (the map over time) or {base_url}/docs while the simulated "
        "robot walks its loop and posts batches.\n"
    )
    scene_id = run_robot(
        base_url, frames=args.frames, frames_per_batch=args.frames_per_batch, pace_seconds=args.pace
    )
    with Client(base_url, timeout=30.0) as client:
        wait_until_processed(client, scene_id)
        print_summary(client, base_url, scene_id)
    if args.exit:
        server.should_exit = True
        thread.join(timeout=30)
        return
    print("\nThe service keeps running; press Ctrl-C to stop it.")
    try:
        while thread.is_alive():
            thread.join(timeout=1.0)
    except KeyboardInterrupt:
        server.should_exit = True
        thread.join(timeout=30)


if __name__ == "__main__":
    main()
