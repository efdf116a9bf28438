"""End-to-end benchmark: real `pbdag` processes over HTTP on loopback, fed at a fixed rate.

    python -m bench.bench_service [--rate 30] [--seconds 20] [--postgres URL] [--quick]

Each batch is one 640x480 frame with 20 object masks and the masks of the fixtures in view (a
long table carrying the objects, a counter and a shelf), rendered once by the simulator while
the camera sways along the table, and posted open loop: every batch has its send time on a fixed
schedule, whatever the previous answers took. Configurations:

- (a) `pbdag serve` on SQLite with its in-process worker, 1 scene;
- (b) PostgreSQL: `pbdag serve --no-worker` + 1 `pbdag worker`, 1 scene;
- (c) PostgreSQL: + 2 workers, 2 scenes (each at --rate);
- (d) PostgreSQL: + 1 worker, 2 scenes (each at --rate), so that (c)/(d) is the two-worker
  scaling measured side by side in one run.

Per configuration: achieved throughput (batches done per second), POST latency, POST-to-done
latency (the batch's `finished_at` minus its scheduled send time, both the wall clock of this
machine, so a send made late by a slow API counts; the send lag is reported), the worker's decide and append times from its /metrics, the CPU seconds of each
process (from /proc) and of the whole machine, and the backlog when the load stops. Every batch
must end done. The figures go to bench/results/service-<time>.json.

The service keeps its defaults except: anonymous loopback access, no rate limit and an
unbounded scene queue (so an overloaded worker shows as a backlog, not as 429s).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import statistics
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import httpx

from bench.perf_common import write_results
from bench.records import Figures, ServiceResult
from bench.service_fleet import Fleet, free_port, machine_busy_seconds, postgres_schema
from bench.service_load import BodyTemplate, render_templates, stage_breakdown
from bench.service_report import GOAL_RATE, percentile, table, verdicts

CLOCK = (
    "latency to done: the batch's finished_at minus its scheduled send time (time.time()), one "
    "machine's wall clock; send_lag_p99_ms is how late sends started"
)
SERVICE_SETTINGS = {  # what the fleet sets beyond the defaults, as the result file records it
    "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
    "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
    "PBDAG_MAX_QUEUED_BATCHES_PER_SCENE": "1000000",
    "PBDAG_LOG_LEVEL": "WARNING",
}
POSTING_THREADS = 128  # concurrent POSTs; beyond, a send waits (its lag is reported)


# --- one configuration ---------------------------------------------------------------------


@dataclass
class Config:
    """One measured set-up."""

    key: str
    title: str
    postgres: bool
    workers: int  # separate `pbdag worker` processes (0: the API's in-process worker)
    scenes: int


CONFIGS = (
    Config("a", "SQLite, serve + in-process worker, 1 scene", False, 0, 1),
    Config("b", "PostgreSQL, serve --no-worker + 1 worker, 1 scene", True, 1, 1),
    Config("c", "PostgreSQL, + 2 workers, 2 scenes", True, 2, 2),
    Config("d", "PostgreSQL, + 1 worker, 2 scenes", True, 1, 2),
)


@dataclass
class Sent:
    """One POST: when it was due and sent, how it was answered, and when the batch was done."""

    scene: str
    batch_id: str
    due: float  # perf_counter
    due_wall: float  # time.time() of the scheduled send
    sent: float = 0.0  # perf_counter
    answered: float = 0.0
    status: int = 0
    finished_at: float | None = None  # the service's time.time()
    state: str = ""
    error: str = ""


def scrape(url: str) -> dict[str, float]:
    """The sums and counts of the worker histograms of one /metrics page."""
    wanted = (
        "pbdag_decide_seconds_sum",
        "pbdag_decide_seconds_count",
        "pbdag_append_seconds_sum",
        "pbdag_append_seconds_count",
    )
    text = httpx.get(url, timeout=10).text
    found: dict[str, float] = {}
    for line in text.splitlines():
        name, _, value = line.partition(" ")
        if name in wanted:
            found[name] = float(value)
    return found


def backlog(http: httpx.Client) -> int:
    counts = http.get("/healthz").json()["batches"]
    return int(sum(counts.get(status, 0) for status in ("queued", "running", "failed")))


def run_config(
    config: Config,
    templates: Sequence[BodyTemplate],
    *,
    rate: float,
    seconds: float,
    postgres_url: str | None,
    drain_timeout: float,
) -> Figures:
    """Start the processes, post the load, wait for the queue to drain, measure, stop."""
    figures = Figures(config.key, config.title, rate, config.scenes, config.workers, seconds)
    with ExitStack() as stack:
        data_dir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="pbdag-bench-")))
        port = free_port()
        url = f"http://127.0.0.1:{port}"
        env = {
            **os.environ,
            "PBDAG_DATA_DIR": str(data_dir),
            "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
            "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
            "PBDAG_MAX_QUEUED_BATCHES_PER_SCENE": "1000000",
            "PBDAG_LOG_LEVEL": "WARNING",
        }
        env.pop("PBDAG_DATABASE_URL", None)
        if config.postgres:
            assert postgres_url is not None
            env["PBDAG_DATABASE_URL"] = stack.enter_context(postgres_schema(postgres_url))
        fleet = Fleet(env, data_dir / "service.log")
        stack.callback(fleet.stop)
        serve = ["serve", "--port", str(port)] + (["--no-worker"] if config.postgres else [])
        fleet.start("api", serve, f"{url}/healthz")
        for index in range(config.workers):
            metrics_port = free_port()
            fleet.start(
                f"worker-{index + 1}",
                ["worker", "--metrics-port", str(metrics_port)],
                f"http://127.0.0.1:{metrics_port}/metrics",
            )
        http = stack.enter_context(httpx.Client(base_url=url, timeout=30.0))
        run = uuid.uuid4().hex[:8]
        scenes = [
            http.post("/v1/scenes", json={"name": f"bench-{run}-{i}"}).json()["id"]
            for i in range(config.scenes)
        ]
        plan = build_plan(scenes, templates, rate, seconds, run)
        figures.batches = len(plan)
        before = Snapshot.take(fleet)
        sends = post_open_loop(url, plan)
        load_end = time.perf_counter()
        figures.backlog_at_end = backlog(http)
        print(f"  load done; backlog {figures.backlog_at_end}, draining", file=sys.stderr)
        while backlog(http) and time.perf_counter() - load_end < drain_timeout:
            time.sleep(0.05)
        figures.drain_seconds = round(time.perf_counter() - load_end, 2)
        after = Snapshot.take(fleet)
        figures.cpu_seconds = {
            name: round(after.cpu[name] - before.cpu[name], 2) for name in after.cpu
        }
        figures.machine_busy_cores = round(
            (after.busy - before.busy) / (after.wall - before.wall), 2
        )
        figures.load_generator_cpu_seconds = round(after.own - before.own, 2)
        worker_metrics = [
            scrape(metrics) for name, metrics in fleet.metrics_urls.items() if name != "api"
        ] or [scrape(f"{url}/metrics")]
        collect(http, sends, figures, worker_metrics)
    print(
        f"  done {figures.done}/{figures.batches}, {figures.throughput:.1f}/s, "
        f"done p99 {figures.done_p99_ms:.0f} ms",
        file=sys.stderr,
    )
    return figures


@dataclass
class Snapshot:
    """CPU counters at one moment: per process, the machine's busy seconds, this process's."""

    cpu: dict[str, float]
    busy: float
    wall: float
    own: float

    @classmethod
    def take(cls, fleet: Fleet) -> Snapshot:
        return cls(fleet.cpu(), machine_busy_seconds()[0], time.perf_counter(), time.process_time())


def build_plan(
    scenes: Sequence[str],
    templates: Sequence[BodyTemplate],
    rate: float,
    seconds: float,
    run: str,
) -> list[tuple[float, str, str, bytes]]:
    """(send offset, scene, batch id, body): one batch per scene every 1/rate s, the scenes
    interleaved; the bodies are joined from the pre-rendered parts before the clock starts."""
    period = 1.0 / rate
    plan = []
    for index in range(round(rate * seconds)):
        for offset, scene in enumerate(scenes):
            batch_id = f"{run}-{offset}-{index:06d}"
            body = templates[index % len(templates)].body(batch_id, index * period)
            plan.append((index * period + offset * period / len(scenes), scene, batch_id, body))
    return plan


def post_open_loop(url: str, plan: Sequence[tuple[float, str, str, bytes]]) -> list[Sent]:
    """Post each batch at its due time from a pool of threads (open loop: a slow answer never
    delays the next send)."""
    sends: list[Sent] = []
    lock = threading.Lock()
    client = httpx.Client(
        base_url=url,
        timeout=60.0,
        limits=httpx.Limits(
            max_connections=POSTING_THREADS, max_keepalive_connections=POSTING_THREADS
        ),
        headers={"content-type": "application/json"},
    )

    def post(record: Sent, body: bytes) -> None:
        record.sent = time.perf_counter()
        try:
            response = client.post(f"/v1/scenes/{record.scene}/batches", content=body)
            record.status = response.status_code
            if response.status_code not in (200, 202):
                record.error = f"{response.status_code}: {response.text[:300]}"
        except httpx.HTTPError as error:
            record.error = repr(error)
        record.answered = time.perf_counter()
        with lock:
            sends.append(record)

    start = time.perf_counter() + 0.1
    start_wall = time.time() + (start - time.perf_counter())
    shown = start
    with client, ThreadPoolExecutor(max_workers=POSTING_THREADS) as pool:
        for offset_s, scene, batch_id, body in plan:
            due = start + offset_s
            delay = due - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            pool.submit(post, Sent(scene, batch_id, due, start_wall + offset_s), body)
            if due - shown >= 5.0:
                shown = due
                print(f"  {due - start:5.1f} s: {len(sends)} answered", file=sys.stderr)
    return sends


def collect(
    http: httpx.Client,
    sends: list[Sent],
    figures: Figures,
    worker_metrics: list[dict[str, float]],
) -> None:
    """Read every batch's final status and fill the figures."""
    for record in sends:
        if record.status not in (200, 202):
            continue
        answer = http.get(f"/v1/scenes/{record.scene}/batches/{record.batch_id}").json()
        record.state, record.finished_at = answer["status"], answer["finished_at"]
        if answer["status"] != "done":
            record.error = f"{answer['status']}: {answer['error']}"
    accepted = [r for r in sends if r.status in (200, 202)]
    done = [r for r in accepted if r.state == "done" and r.finished_at is not None]
    figures.accepted, figures.done = len(accepted), len(done)
    figures.errors = sorted({r.error for r in sends if r.error})[:5]
    figures.send_lag_p99_ms = round(percentile([(r.sent - r.due) * 1e3 for r in sends], 99), 2)
    post_ms = [(r.answered - r.sent) * 1e3 for r in accepted]
    figures.post_p50_ms = round(percentile(post_ms, 50), 1)
    figures.post_p99_ms = round(percentile(post_ms, 99), 1)
    if done:
        # From the scheduled send, so that a late send (all posting threads waiting on a slow
        # API) counts against the service rather than hiding its delay.
        latency = [(r.finished_at - r.due_wall) * 1e3 for r in done if r.finished_at]
        figures.done_p50_ms = round(percentile(latency, 50), 1)
        figures.done_p99_ms = round(percentile(latency, 99), 1)
        figures.done_max_ms = round(max(latency), 1)
        first = min(r.due_wall for r in done)
        last = max(r.finished_at for r in done if r.finished_at)
        figures.throughput = round(len(done) / (last - first), 2)
    sums = {key: sum(m.get(key, 0.0) for m in worker_metrics) for key in worker_metrics[0]}
    if sums.get("pbdag_decide_seconds_count"):
        figures.decide_mean_ms = round(
            1e3 * sums["pbdag_decide_seconds_sum"] / sums["pbdag_decide_seconds_count"], 1
        )
    if sums.get("pbdag_append_seconds_count"):
        figures.append_mean_ms = round(
            1e3 * sums["pbdag_append_seconds_sum"] / sums["pbdag_append_seconds_count"], 1
        )


# --- the run -------------------------------------------------------------------------------


def interrupted(signum: int, _frame: object) -> None:
    """SIGTERM unwinds like Ctrl-C, through the clean-up of the processes and the schema."""
    raise KeyboardInterrupt(f"signal {signum}")


def arguments(argv: list[str] | None) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=30.0, help="batches per second per scene")
    parser.add_argument("--seconds", type=float, default=20.0, help="load per configuration")
    parser.add_argument(
        "--postgres", metavar="URL", help="PostgreSQL server for (b)-(d) (a fresh schema each)"
    )
    parser.add_argument("--quick", action="store_true", help="3 s per configuration")
    parser.add_argument(
        "--configs", default="abcd", help="which configurations (PostgreSQL ones need --postgres)"
    )
    parser.add_argument(
        "--ramp",
        metavar="RATES",
        default="",
        help="comma-separated rates (e.g. 4,6,8,10): one worker on one scene at each, 10 s "
        "(3 s with --quick), for the highest rate it sustains",
    )
    parser.add_argument("--views", type=int, default=24, help="distinct rendered views cycled")
    parser.add_argument("--name", default=None, help="result file name (default service-<time>)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    args = arguments(argv)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, interrupted)  # stop the processes, drop the schema
    seconds = 3.0 if args.quick else args.seconds
    chosen = [c for c in CONFIGS if c.key in args.configs and (args.postgres or not c.postgres)]
    skipped = [c.key for c in CONFIGS if c.key in args.configs and c not in chosen]
    if skipped:
        print(f"skipping {', '.join(skipped)}: no --postgres URL", file=sys.stderr)
    started = time.perf_counter()
    load_average = [round(v, 2) for v in os.getloadavg()]
    templates = render_templates(8 if args.quick else args.views)
    sizes = [len(t.body("x" * 20, 0.0)) for t in templates]
    print(
        f"rendered {len(templates)} views: {templates[0].objects} objects + "
        f"{min(t.fixtures for t in templates)}-{max(t.fixtures for t in templates)} fixture "
        f"masks per 640x480 frame, {statistics.mean(sizes) / 1e6:.2f} MB per body, "
        f"{time.perf_counter() - started:.1f} s",
        file=sys.stderr,
    )
    breakdown = stage_breakdown(templates, 10 if args.quick else 40, GOAL_RATE)
    print(f"one batch's CPU stages in one process, median ms: {breakdown}", file=sys.stderr)
    rows: dict[str, Figures] = {}
    for config in chosen:
        print(f"({config.key}) {config.title} at {args.rate:g}/s per scene", file=sys.stderr)
        rows[config.key] = run_config(
            config,
            templates,
            rate=args.rate,
            seconds=seconds,
            postgres_url=args.postgres,
            drain_timeout=max(60.0, 10 * seconds),
        )
    ramp = [float(r) for r in args.ramp.split(",")] if args.ramp else []
    base = next((c for c in CONFIGS if c.key == ("b" if args.postgres else "a")), CONFIGS[0])
    for rate in ramp:
        key = f"{base.key}@{rate:g}"
        step = Config(key, f"{base.title}, ramp", base.postgres, base.workers, base.scenes)
        print(f"({key}) ramp step at {rate:g}/s", file=sys.stderr)
        rows[key] = run_config(
            step,
            templates,
            rate=rate,
            seconds=min(seconds, 10.0),
            postgres_url=args.postgres,
            drain_timeout=60.0,
        )
    print(
        f"\nPBD-AG end to end over HTTP: one 640x480 frame per batch ({templates[0].objects} "
        f"object masks + fixture masks), open loop at {args.rate:g}/s per scene for {seconds:g} s; "
        f"{os.cpu_count()} cores shared by the API, the workers, PostgreSQL and this load generator"
    )
    for f in rows.values():
        print(f"  ({f.config}) {f.title}")
    print(table(list(rows.values())))
    found = verdicts(rows, args.rate, ramp)
    print(f"CPU stages of one batch in one process (median ms): {json.dumps(breakdown)}")
    print(f"load average before the run: {load_average} (other users of the machine count)")
    for name, verdict in dataclasses.asdict(found).items():
        if verdict is not None:
            print(f"{name}: {json.dumps(verdict)}")
    stamp = time.strftime("%Y%m%d-%H%M%S")
    write_results(
        args.name or f"service-{stamp}",
        ServiceResult(
            benchmark="service end to end",
            rate_per_scene=args.rate,
            seconds=seconds,
            body_bytes_mean=int(statistics.mean(sizes)),
            object_masks=templates[0].objects,
            fixture_masks=[t.fixtures for t in templates],
            clock=CLOCK,
            service_settings=SERVICE_SETTINGS,
            load_average_at_start=load_average,
            stage_breakdown_ms=breakdown,
            configs=rows,
            goals=found,
        ),
    )


if __name__ == "__main__":
    main()
