"""A scripted fault run: clients post batches while processes are SIGKILLed at random moments.

    python -m tests.e2e.fault_run [--kills 40] [--postgres-restart] [--poison] [--sqlite]
                                  [--blob-backend auto|postgres|folder]

On PostgreSQL (default): `pbdag serve --no-worker` and two `pbdag worker`s; on SQLite one
`pbdag serve` with its worker. Client threads post batches to two scenes and retry each until it
is accepted (a re-post is idempotent); a killer SIGKILLs a random process every 0.3-1.2 s and
restarts it. On PostgreSQL the blobs are in the database by default and each process has its
own data directory (`--blob-backend folder`: one shared folder). Optionally PostgreSQL itself
is restarted once mid-run, and a poison batch is mixed in (accepted by the API, refused by the
workers, whose limits are tighter). At the end every
accepted batch must be done exactly once (the poison: dead, with a `batch_skipped` event), each
scene's seqs gapless, and `pbdag rebuild` must find no difference. Everything stays on loopback.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import httpx

PBDAG = [sys.executable, "-m", "service.cli"]
REPO = Path(__file__).resolve().parents[2]
POISON = "poison-0"


@dataclass
class FaultReport:
    """What a fault run did and found."""

    backend: str
    blobs: str = "folder"  # where the raw batches were kept
    kills: int = 0
    kills_by_process: dict[str, int] = field(default_factory=dict)
    postgres_restarts: int = 0
    batches_accepted: int = 0
    batches_done: int = 0
    events: int = 0
    gaps: int = 0
    duplicates: int = 0
    lost: list[str] = field(default_factory=list)
    poison: str | None = None  # the poison batch's final status, when one was mixed in
    rebuild_exit_code: int | None = None
    seconds: float = 0.0

    @property
    def clean(self) -> bool:
        """No gap, no duplicate, no lost batch, a rebuild without difference, the poison dead."""
        return (
            self.gaps == 0
            and self.duplicates == 0
            and not self.lost
            and self.rebuild_exit_code == 0
            and self.poison in (None, "dead")
        )


def free_port() -> int:
    """A free TCP port on loopback."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class Fleet:
    """The service's processes, started, killed and restarted by name."""

    def __init__(self, commands: dict[str, list[str]], envs: dict[str, dict[str, str]], log: Path):
        self.commands, self.envs, self.log = commands, envs, log
        self.processes: dict[str, subprocess.Popen[bytes]] = {}
        for name in commands:
            self.start(name)

    def start(self, name: str) -> None:
        with self.log.open("ab") as handle:
            self.processes[name] = subprocess.Popen(
                [*PBDAG, *self.commands[name]],
                env=self.envs[name],
                cwd=REPO,
                stdout=handle,
                stderr=subprocess.STDOUT,
            )

    def kill(self, name: str) -> None:
        process = self.processes[name]
        process.send_signal(signal.SIGKILL)
        process.wait()

    def stop(self) -> None:
        for process in self.processes.values():
            process.terminate()
        for process in self.processes.values():
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()


def wait_healthy(url: str, timeout: float = 60.0) -> None:
    """Poll /healthz until it answers."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/healthz", timeout=1.0).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"{url} did not become healthy within {timeout} s")


def restart_postgres() -> str | None:
    """Restart the local PostgreSQL cluster; None when done, else why it could not be."""
    if shutil.which("pg_ctlcluster") is None or not Path("/etc/postgresql").is_dir():
        return "pg_ctlcluster is not available"
    version = sorted(os.listdir("/etc/postgresql"))[-1]
    command = ["pg_ctlcluster", "--skip-systemctl-redirect", version, "main", "restart"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    return None if result.returncode == 0 else result.stderr.strip() or "restart failed"


def bodies(count: int) -> list[dict[str, Any]]:
    """One-frame batches (the mug in front of a wall), reused under fresh batch ids."""
    from tests.wire_scenes import batch

    return [batch(f"template-{i}", i) for i in range(count)]


def poisoned(body: dict[str, Any]) -> dict[str, Any]:
    """A batch the API accepts and the workers refuse: more class scores than their limit."""
    frame = json.loads(json.dumps(body["frames"][0]))
    frame["detections"][0]["class_scores"] = {f"class{i}": 0.1 for i in range(10)}
    return {"batch_id": POISON, "frames": [frame]}


def run_fault_run(
    *,
    kills: int,
    data_dir: Path,
    database_url: str | None,
    postgres_restart: bool = False,
    poison: bool = False,
    clients: int = 3,
    seed: int = 7,
    progress: bool = True,
    blob_backend: str = "auto",
) -> FaultReport:
    """Run the faults, wait for the queue to settle, and check the log (see the module doc).

    `blob_backend` is PBDAG_BLOB_BACKEND; with the blobs in PostgreSQL (auto on PostgreSQL)
    each process gets its own data directory, as on separate hosts."""
    started = time.monotonic()
    rng = random.Random(seed)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    base_env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(data_dir),
        "PBDAG_LEASE_SECONDS": "3",
        "PBDAG_RETRY_BASE_SECONDS": "0.2",
        "PBDAG_RETRY_MAX_SECONDS": "2",
        "PBDAG_MAX_ATTEMPTS": "20",  # kills and a database restart are passing failures
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
    }
    base_env.pop("PBDAG_DATABASE_URL", None)
    base_env["PBDAG_BLOB_BACKEND"] = blob_backend
    if database_url is not None:
        base_env["PBDAG_DATABASE_URL"] = database_url
        commands = {
            "api": ["serve", "--port", str(port), "--no-worker"],
            "worker-1": ["worker"],
            "worker-2": ["worker"],
        }
    else:
        commands = {"api": ["serve", "--port", str(port)]}
    if poison and database_url is None:
        raise ValueError("the poison batch needs separate workers, hence PostgreSQL")
    # The workers' tighter limit is what makes the poison batch fail (a deployment whose limits
    # changed between accepting and processing a batch).
    worker_env = {**base_env, "PBDAG_MAX_CLASS_SCORES": "5"} if poison else base_env
    envs = {name: base_env if name == "api" else worker_env for name in commands}
    blobs_in_postgres = database_url is not None and blob_backend in ("auto", "postgres")
    if blobs_in_postgres:  # nothing shared but the database
        envs = {name: {**env, "PBDAG_DATA_DIR": str(data_dir / name)} for name, env in envs.items()}
    report = FaultReport(
        backend="postgres" if database_url else "sqlite",
        blobs="postgres" if blobs_in_postgres else "folder",
    )
    log = data_dir / "fault-run.log"
    data_dir.mkdir(parents=True, exist_ok=True)
    fleet = Fleet(commands, envs, log)
    wait_healthy(url)
    with httpx.Client(base_url=url, timeout=10.0) as setup:
        scenes = [
            setup.post("/v1/scenes", json={"name": f"fault-{i}"}).json()["id"] for i in range(2)
        ]
    templates = bodies(6)
    accepted: dict[str, set[str]] = defaultdict(set)
    lock = threading.Lock()
    stop = threading.Event()

    def post_until_accepted(http: httpx.Client, scene: str, body: dict[str, Any]) -> None:
        while True:  # an accepted batch must be known, even when the run is stopping
            try:
                response = http.post(f"/v1/scenes/{scene}/batches", json=body)
            except httpx.TransportError:
                time.sleep(0.2)  # the API is down for a moment
                continue
            if response.status_code in (200, 202):
                with lock:
                    accepted[scene].add(body["batch_id"])
                return
            if response.status_code in (429, 500, 503):
                time.sleep(0.2)
                continue
            raise RuntimeError(f"batch {body['batch_id']}: {response.status_code} {response.text}")

    def client_loop(index: int) -> None:
        with httpx.Client(base_url=url, timeout=10.0) as http:
            sequence = 0
            while not stop.is_set():
                scene = scenes[(index + sequence) % len(scenes)]
                body = dict(templates[sequence % len(templates)])
                body["batch_id"] = f"c{index}-{sequence:05d}"
                post_until_accepted(http, scene, body)
                sequence += 1

    threads = [threading.Thread(target=client_loop, args=(i,), daemon=True) for i in range(clients)]
    for thread in threads:
        thread.start()
    if poison:
        with httpx.Client(base_url=url, timeout=10.0) as http:
            post_until_accepted(http, scenes[0], poisoned(templates[0]))
    kills_by: dict[str, int] = defaultdict(int)
    restart_at = kills // 2 if postgres_restart and database_url else None
    try:
        while report.kills < kills:
            time.sleep(rng.uniform(0.3, 1.2))
            name = rng.choice(sorted(commands))
            fleet.kill(name)
            report.kills += 1
            kills_by[name] += 1
            if report.kills == restart_at:
                why_not = restart_postgres()
                if why_not is not None:
                    raise RuntimeError(f"could not restart PostgreSQL: {why_not}")
                report.postgres_restarts += 1
            time.sleep(rng.uniform(0.0, 0.5))
            fleet.start(name)
            if name == "api":
                wait_healthy(url)
            if progress:
                print(f"fault run: {report.kills}/{kills} kills ({name})", file=sys.stderr)
        stop.set()
        for thread in threads:
            thread.join(timeout=60)
        report.kills_by_process = dict(kills_by)
        settle(url, accepted, report)
    finally:
        stop.set()
        fleet.stop()
    rebuild = subprocess.run(
        [*PBDAG, "rebuild"], env=base_env, cwd=REPO, capture_output=True, text=True, timeout=600
    )
    report.rebuild_exit_code = rebuild.returncode
    if rebuild.returncode != 0:
        print(rebuild.stdout[-2000:], rebuild.stderr[-2000:], file=sys.stderr)
    report.seconds = time.monotonic() - started
    return report


def settle(url: str, accepted: dict[str, set[str]], report: FaultReport) -> None:
    """Wait until every accepted batch finished, then check the logs."""
    with httpx.Client(base_url=url, timeout=30.0) as http:
        deadline = time.monotonic() + 300
        statuses: dict[tuple[str, str], str] = {}
        while time.monotonic() < deadline:
            statuses = {
                (scene, batch): http.get(f"/v1/scenes/{scene}/batches/{batch}").json()["status"]
                for scene, batch_ids in accepted.items()
                for batch in batch_ids
            }
            if all(status in ("done", "dead") for status in statuses.values()):
                break
            time.sleep(0.5)
        report.batches_accepted = len(statuses)
        report.batches_done = sum(status == "done" for status in statuses.values())
        report.lost = sorted(
            f"{scene}/{batch}"
            for (scene, batch), status in statuses.items()
            if status != "done" and batch != POISON
        )
        poison = [status for (_, batch), status in statuses.items() if batch == POISON]
        report.poison = poison[0] if poison else None
        for scene in accepted:
            check_log(http, scene, statuses, report)


def check_log(
    http: httpx.Client, scene: str, statuses: dict[tuple[str, str], str], report: FaultReport
) -> None:
    """Gapless seqs; each batch's events appended once, in one run, matching its seq range."""
    events: list[dict[str, Any]] = []
    after: int | None = -1
    while after is not None:
        page = http.get(f"/v1/scenes/{scene}/events", params={"after": after, "limit": 1000}).json()
        events += page["events"]
        after = page["next_after"]
    report.events += len(events)
    report.gaps += sum(1 for i, event in enumerate(events) if event["seq"] != i)
    runs: dict[str, list[tuple[int, int]]] = defaultdict(list)
    for event in events:
        batch = event["batch_id"]
        if batch is None:
            continue
        if runs[batch] and runs[batch][-1][1] == event["seq"] - 1:
            runs[batch][-1] = (runs[batch][-1][0], event["seq"])
        else:
            runs[batch].append((event["seq"], event["seq"]))
    report.duplicates += sum(len(ranges) - 1 for ranges in runs.values())
    for (scene_id, batch), status in statuses.items():
        if scene_id != scene or status != "done":
            continue
        record = http.get(f"/v1/scenes/{scene}/batches/{batch}").json()
        expected = (
            [] if record["first_seq"] is None else [(record["first_seq"], record["last_seq"])]
        )
        if runs.get(batch, []) != expected:
            report.duplicates += 1


def main(argv: list[str] | None = None) -> int:
    """Command line; prints the report as JSON and exits 1 unless it is clean."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kills", type=int, default=40)
    parser.add_argument("--sqlite", action="store_true", help="one `pbdag serve` on SQLite")
    parser.add_argument(
        "--postgres-url",
        default=os.environ.get(
            "PBDAG_TEST_POSTGRES_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
        ),
    )
    parser.add_argument("--postgres-restart", action="store_true")
    parser.add_argument("--poison", action="store_true")
    parser.add_argument("--clients", type=int, default=3)
    parser.add_argument(
        "--blob-backend",
        choices=("auto", "postgres", "folder"),
        default="auto",
        help="PBDAG_BLOB_BACKEND (auto: in PostgreSQL on PostgreSQL, each process with its own "
        "data directory)",
    )
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="pbdag-fault-") as temp:
        database_url = None
        schema = None
        if not args.sqlite:
            import sqlalchemy as sa

            schema = f"fault_{os.getpid()}"
            admin = sa.create_engine(args.postgres_url, pool_pre_ping=True)  # survives the restart
            with admin.begin() as connection:
                connection.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
            database_url = f"{args.postgres_url}?options=-csearch_path%3D{schema}"
        try:
            report = run_fault_run(
                kills=args.kills,
                data_dir=Path(temp),
                database_url=database_url,
                postgres_restart=args.postgres_restart,
                poison=args.poison,
                clients=args.clients,
                blob_backend=args.blob_backend,
            )
        finally:
            if schema is not None:
                with admin.begin() as connection:
                    connection.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
    print(json.dumps({**asdict(report), "clean": report.clean}, indent=2))
    return 0 if report.clean else 1


if __name__ == "__main__":
    sys.exit(main())
