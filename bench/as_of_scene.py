"""A developer's loop for `as_of`: build the 1M-event scene once, then time `load_state` on it
as often as needed (the `as-of` benchmark builds and drops its scene on every run).

    python -m bench.as_of_scene build   URL [--events 1000000] [--snapshot-interval 500]
    python -m bench.as_of_scene time    URL [--queries 50] [--seed 0]
    python -m bench.as_of_scene steps   URL [--queries 50] [--seed 0]
    python -m bench.as_of_scene compare URL [URL ...] [--tree DIR ...] [--rounds 6]
    python -m bench.as_of_scene rewrite URL [--interval 250]

URL is a SQLite URL (`sqlite:////tmp/asof.db`) or a PostgreSQL database (create it first:
`createdb -h 127.0.0.1 -U postgres asof`); `build` migrates it and writes one scene, the same
stream and snapshots as `bench_store as-of`. `time` asks `load_state` for random seqs of the
scene the database holds and prints the latencies as JSON. `compare` runs `time` in
subprocesses, round by round and taking turns (each pair: one URL with the code of one tree,
by default this checkout), so that two databases, or two versions of the code, are judged side
by side on a loaded machine; it prints each variant's median of the rounds' medians and their
ratio. `rewrite` re-encodes every snapshot in the current body version (as `pbdag rebuild`
does), so that a copy of a database can carry the new snapshots while the original keeps the
old ones.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import sqlalchemy as sa
from tqdm import tqdm

from bench.bench_store import append_all, snapshot_storage
from bench.store_appenders import new_scene
from core.evolve import fold
from service.settings import Settings
from service.store.engine import (
    gc_paused,
    make_engine,
    migrate,
    read_transaction,
    write_transaction,
)
from service.store.event_log import EventLog, decoded_event
from service.store.snapshot_codec import SNAPSHOT_VERSION, decode_snapshot
from service.store.tables import events, scenes, snapshots

HERE = Path(__file__).resolve().parents[1]


def the_scene(engine: sa.Engine) -> str:
    """The id of the one scene the database holds."""
    with engine.connect() as connection:
        ids = connection.execute(sa.select(scenes.c.id)).scalars().all()
    if len(ids) != 1:
        sys.exit(f"expected one scene, found {len(ids)}")
    return str(ids[0])


def build(args: argparse.Namespace) -> None:
    """Migrate the database and write the benchmark's scene into it."""
    engine = make_engine(args.url)
    migrate(engine)
    log = EventLog(engine)
    scene = new_scene(log)
    batch = min(1000, args.snapshot_interval) if args.snapshot_interval > 0 else 1000
    started = time.perf_counter()
    append_all(log, scene.id, args.events - 1, batch, args.snapshot_interval, progress=True)
    storage = snapshot_storage(engine)
    print(
        f"scene {scene.id}: {args.events:,} events, {storage.snapshots:,} snapshots of "
        f"{storage.snapshot_bytes / max(storage.snapshots, 1) / 1e3:,.0f} kB "
        f"({storage.snapshot_bytes / args.events:,.0f} bytes per event), "
        f"built in {time.perf_counter() - started:.0f} s"
    )


def time_load_state(args: argparse.Namespace) -> None:
    """Latencies of `load_state` at random seqs, as JSON on stdout."""
    engine = make_engine(args.url)
    log = EventLog(engine)
    scene_id = the_scene(engine)
    head = log.scene(scene_id).head_seq
    targets = np.random.default_rng(args.seed).integers(1, head + 1, size=args.queries)
    log.load_state(scene_id, int(targets[0]))  # warm: the connection, the imports
    latencies = []
    for target in targets:
        started = time.perf_counter()
        log.load_state(scene_id, int(target))
        latencies.append(1000 * (time.perf_counter() - started))
    print(json.dumps(latencies))


def steps(args: argparse.Namespace) -> None:
    """Where the time of `load_state` goes: its steps timed one by one at random seqs (medians,
    collector paused as `load_state` pauses it)."""
    engine = make_engine(args.url)
    log = EventLog(engine)
    scene_id = the_scene(engine)
    head = log.scene(scene_id).head_seq
    targets = np.random.default_rng(args.seed).integers(1, head + 1, size=args.queries)
    laps: dict[str, list[float]] = {}
    for target in [int(targets[0]), *map(int, targets)]:
        with gc_paused(), read_transaction(engine) as connection:
            started = time.perf_counter()
            connection.execute(sa.select(scenes.c.head_seq).where(scenes.c.id == scene_id))
            marks = [("the scene's head", time.perf_counter())]
            found = log.snapshot_row(connection, scene_id, target)
            assert found is not None
            version, body = found
            marks.append(("reading the snapshot", time.perf_counter()))
            base = decode_snapshot(body, version)
            marks.append(("decoding it", time.perf_counter()))
            rows = connection.execute(
                sa.select(events.c.seq, events.c.type, events.c.track_id, events.c.state)
                .add_columns(events.c.frame_id, events.c.details)
                .where(events.c.scene_id == scene_id, events.c.seq > base.head_seq)
                .where(events.c.seq <= target)
                .order_by(events.c.seq)
            ).all()
            marks.append(("reading the events after it", time.perf_counter()))
            typed = [
                decoded_event(row.seq, row.type, row.track_id, row.state, row.frame_id, row.details)
                for row in rows
            ]
            marks.append(("decoding them", time.perf_counter()))
            fold(base, typed)
            marks.append(("folding them", time.perf_counter()))
        for name, mark in marks:
            laps.setdefault(name, []).append(1000 * (mark - started))
            started = mark
    total = 0.0
    for name, values in laps.items():
        median = statistics.median(values[1:])  # the first warms up
        total += median
        print(f"{name:<30}{median:8.2f} ms")
    print(f"{'sum of the medians':<30}{total:8.2f} ms")


def compare(args: argparse.Namespace) -> None:
    """`time` in subprocesses, interleaved round by round, one variant per (URL, tree) pair."""
    trees = args.tree or [str(HERE)]
    urls = args.url
    if len(trees) == 1:
        trees = trees * len(urls)
    if len(urls) == 1:
        urls = urls * len(trees)
    variants = list(zip(urls, trees, strict=True))
    medians: dict[int, list[float]] = {i: [] for i in range(len(variants))}
    for round_index in range(args.rounds):
        shift = round_index % len(variants)
        for index in [*range(shift, len(variants)), *range(shift)]:
            url, tree = variants[index]
            command = [sys.executable, str(Path(__file__).resolve()), "time", url]
            command += ["--queries", str(args.queries), "--seed", str(round_index)]
            environment = {**os.environ, "PYTHONPATH": tree}
            output = subprocess.run(
                command, cwd=tree, env=environment, check=True, capture_output=True, text=True
            ).stdout
            medians[index].append(statistics.median(json.loads(output)))
    first = statistics.median(medians[0])
    for index, (url, tree) in enumerate(variants):
        median = statistics.median(medians[index])
        rounds = ", ".join(f"{m:.1f}" for m in medians[index])
        print(
            f"{url} ({tree}): median {median:.1f} ms, {median / first:.2f}x the first "
            f"(rounds: {rounds})"
        )


def rewrite(args: argparse.Namespace) -> None:
    """Re-encode every snapshot of the database not in the current body version; with
    `--interval`, also add the snapshots a smaller interval would have taken (the state at each
    multiple of it, as the worker folds it)."""
    engine = make_engine(args.url)
    log = EventLog(engine)
    scene_id = the_scene(engine)
    with engine.connect() as connection:
        formats = dict(
            connection.execute(
                sa.select(snapshots.c.seq, snapshots.c.format_version).where(
                    snapshots.c.scene_id == scene_id
                )
            ).all()
        )
    seqs = [seq for seq, version in formats.items() if version != SNAPSHOT_VERSION]
    head = log.scene(scene_id).head_seq
    added = sorted(set(range(args.interval, head + 1, args.interval)) - set(formats))
    for seq in tqdm(sorted([*seqs, *added]), unit="snapshot", file=sys.stderr):
        state = log.load_state(scene_id, seq)
        with write_transaction(engine) as connection:
            connection.execute(
                sa.delete(snapshots).where(snapshots.c.scene_id == scene_id, snapshots.c.seq == seq)
            )
            log.save_snapshot(connection, scene_id, state)
    storage = snapshot_storage(engine)
    print(
        f"{len(seqs):,} snapshots rewritten, {len(added):,} added: {storage.snapshots:,} of "
        f"{storage.snapshot_bytes / max(storage.snapshots, 1) / 1e3:,.0f} kB "
        f"({storage.snapshot_bytes / (head + 1):,.0f} bytes per event)"
    )


def main(argv: list[str] | None = None) -> None:
    """Command line."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    make = commands.add_parser("build")
    make.add_argument("url")
    make.add_argument("--events", type=int, default=1_000_000)
    make.add_argument(
        "--snapshot-interval",
        type=int,
        default=Settings.model_fields["snapshot_interval"].default,
    )
    timing = commands.add_parser("time")
    timing.add_argument("url")
    timing.add_argument("--queries", type=int, default=50)
    timing.add_argument("--seed", type=int, default=0)
    versus = commands.add_parser("compare")
    versus.add_argument("url", nargs="+")
    versus.add_argument("--tree", action="append", help="a checkout whose code to run")
    versus.add_argument("--queries", type=int, default=50)
    versus.add_argument("--rounds", type=int, default=6)
    parts = commands.add_parser("steps")
    parts.add_argument("url")
    parts.add_argument("--queries", type=int, default=50)
    parts.add_argument("--seed", type=int, default=0)
    again = commands.add_parser("rewrite")
    again.add_argument("url")
    again.add_argument("--interval", type=int, default=10**12, help="add snapshots at multiples")
    args = parser.parse_args(argv)
    handlers = {
        "build": build,
        "time": time_load_state,
        "steps": steps,
        "compare": compare,
        "rewrite": rewrite,
    }
    handlers[args.command](args)


if __name__ == "__main__":
    main()
