"""Benchmarks of the store: events appended per second, and as_of against a full replay.

    python -m bench.bench_store append [--events 50000] [--batch 500] [--postgres URL]
    python -m bench.bench_store as-of  [--events 1000000] [--queries 50] [--postgres URL]
    python -m bench.bench_store versus [--rounds 5] [--postgres URL]
    python -m bench.bench_store raw    [--frames 40]

SQLite (a temporary file) always; PostgreSQL too when --postgres is given (a fresh schema,
dropped afterwards). Figures are printed and written to bench/results/store-*.json.

`versus` compares our log append (the expected-head update and the event rows, in one write
transaction, as the worker appends) with the application recorder of the `eventsourcing`
library (the `bench` extra: `pip install -e '.[bench]'`), interleaved round by round on the
same events (about 1 kB of JSON each) in batches of 1, 20 and 500; the library runs twice: with
one aggregate for the whole stream, and with one aggregate per track (its primary key then
indexes each track's history, as our `(scene_id, track_id, seq)` index does).

`raw` measures how raw batches are kept, on the end-to-end benchmark's realistic 640x480 frames
(20 object masks plus fixture masks, png16 Kinect-noise depth; bench/service_load.py): bytes
per frame as canonical JSON with base64 depth (the former blob) and in the compact format
(binary depth, zstandard), the encode and decode time per frame, and the bytes per event of
the events the same frames append (decide + fold, steady state).
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
import orjson
import sqlalchemy as sa
from tqdm import tqdm

from bench.perf_common import synthetic_events, write_results
from bench.records import (
    AppendRate,
    AppendResult,
    AsOfBackend,
    AsOfResult,
    RawResult,
    SnapshotStorage,
    VersusResult,
    VersusRow,
)
from bench.store_appenders import (
    VERSUS_BATCHES,
    VERSUS_EVENTS,
    OurAppender,
    TheirAppender,
    appended_per_second,
    new_scene,
    ratio_range,
)
from core.evolve import fold
from service.settings import Settings
from service.store.engine import make_engine, migrate, write_transaction
from service.store.event_log import EventLog, snapshot_due
from service.store.tables import snapshots


@contextmanager
def engines(postgres_url: str | None) -> Iterator[list[tuple[str, sa.Engine]]]:
    """A migrated SQLite file, and a fresh PostgreSQL schema when a URL is given."""
    with tempfile.TemporaryDirectory() as folder:
        built = [("sqlite", make_engine(f"sqlite:///{Path(folder) / 'bench.db'}"))]
        schema = f"pbdag_bench_{uuid.uuid4().hex[:8]}"
        if postgres_url:
            with sa.create_engine(postgres_url).begin() as connection:
                connection.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
            built.append(
                (
                    "postgres",
                    make_engine(postgres_url, connect_args={"options": f"-csearch_path={schema}"}),
                )
            )
        for _, engine in built:
            migrate(engine)
        try:
            yield built
        finally:
            for _, engine in built:
                engine.dispose()
            if postgres_url:
                with sa.create_engine(postgres_url).begin() as connection:
                    connection.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))


def append_all(
    log: EventLog,
    scene_id: str,
    n_events: int,
    batch: int,
    snapshot_interval: int = 0,
    progress: bool = False,
) -> float:
    """Append a synthetic log in batches (with snapshots when asked); seconds spent in the store."""
    state = log.load_state(scene_id)  # seq 0: the scene's creation, with its name and params
    head, store_seconds = state.head_seq, 0.0
    stream = synthetic_events(n_events)
    bar = tqdm(
        total=n_events, unit="event", disable=not progress, file=sys.stderr, desc="appending"
    )
    while chunk := list(itertools.islice(stream, batch)):
        new_state = fold(state, chunk) if snapshot_interval else state
        started = time.perf_counter()
        with write_transaction(log.engine) as connection:
            log.append(connection, scene_id, head, chunk)
            if snapshot_interval and snapshot_due(head, head + len(chunk), snapshot_interval):
                log.save_snapshot(connection, scene_id, new_state)
        store_seconds += time.perf_counter() - started
        head += len(chunk)
        state = new_state
        bar.update(len(chunk))
    bar.close()
    return store_seconds


def bench_append(args: argparse.Namespace) -> None:
    """Events appended per second, in batches, per backend."""
    rates: dict[str, AppendRate] = {}
    with engines(args.postgres) as built:
        for name, engine in built:
            log = EventLog(engine)
            scene = new_scene(log)
            seconds = append_all(log, scene.id, args.events, args.batch)
            rate = args.events / seconds
            rates[name] = AppendRate(seconds=seconds, events_per_s=rate)
            print(
                f"{name:>8}: {rate:,.0f} events/s appended in batches of {args.batch} (goal > 20,000)"
            )
    results = AppendResult(
        events=args.events,
        batch=args.batch,
        goal_events_per_s=20000,
        sqlite=rates.get("sqlite"),
        postgres=rates.get("postgres"),
    )
    write_results("store-append", results)


def bench_as_of(args: argparse.Namespace) -> None:
    """as_of latency (snapshot + tail) on a long log against a full replay."""
    rows: dict[str, AsOfBackend] = {}
    rng = np.random.default_rng(0)
    with engines(args.postgres) as built:
        for name, engine in built:
            log = EventLog(engine)
            scene = new_scene(log)
            print(
                f"{name}: writing {args.events:,} events with a snapshot every {args.snapshot_interval} ..."
            )
            # Batches no longer than the interval, so that a snapshot lands on every multiple.
            batch = min(1000, args.snapshot_interval) if args.snapshot_interval > 0 else 1000
            started = time.perf_counter()
            append_all(log, scene.id, args.events - 1, batch, args.snapshot_interval, progress=True)
            build_seconds = time.perf_counter() - started
            head = log.scene(scene.id).head_seq
            targets = rng.integers(1, head + 1, size=args.queries)
            latencies = []
            for target in targets:
                started = time.perf_counter()
                log.load_state(scene.id, int(target))
                latencies.append(1000 * (time.perf_counter() - started))
            started = time.perf_counter()
            replayed = log.replay(scene.id)
            replay_ms = 1000 * (time.perf_counter() - started)
            check = log.load_state(scene.id)
            assert check.to_dict() == replayed.to_dict(), "snapshot + tail differs from the replay"
            median = statistics.median(latencies)
            storage = snapshot_storage(engine)
            row = rows[name] = AsOfBackend(
                head_seq=head,
                as_of_median_ms=median,
                as_of_p90_ms=statistics.quantiles(latencies, n=10)[-1],
                full_replay_ms=replay_ms,
                speedup=replay_ms / median,
                database_bytes=database_bytes(engine),
                snapshots=storage.snapshots,
                snapshot_bytes=storage.snapshot_bytes,
                build_seconds=build_seconds,
            )
            print(
                f"{name:>8}: as_of median {median:.1f} ms (p90 {row.as_of_p90_ms:.1f}) vs full replay "
                f"{replay_ms / 1000:.1f} s: {replay_ms / median:,.0f}x faster (goal < 20 ms and >= 50x)"
            )
            print(
                f"{'':>8}  {row.snapshots:,} snapshots, {row.snapshot_bytes / 1e6:,.0f} MB "
                f"({row.snapshot_bytes / head:,.0f} bytes per event; the database "
                f"{row.database_bytes / 1e6:,.0f} MB); built in {build_seconds:.0f} s"
            )
    results = AsOfResult(
        events=args.events,
        snapshot_interval=args.snapshot_interval,
        sqlite=rows.get("sqlite"),
        postgres=rows.get("postgres"),
    )
    write_results("store-as-of", results)


def bench_versus(args: argparse.Namespace) -> None:
    """Ours against eventsourcing's recorder, interleaved round by round, per backend and batch."""
    try:
        peer = "eventsourcing " + version("eventsourcing")
        version("psycopg-pool")
    except PackageNotFoundError:
        sys.exit("bench_store versus needs the bench extra: pip install -e '.[bench]'")
    stream = list(synthetic_events(max(VERSUS_EVENTS.values())))
    sizes = [len(orjson.dumps(event.details())) for event in stream]
    by_backend: dict[str, dict[str, VersusRow]] = {}
    print(f"events of {statistics.fmean(sizes):,.0f} bytes of JSON on average")
    with engines(args.postgres) as built, tempfile.TemporaryDirectory() as folder:
        for name, engine in built:
            pair: list[OurAppender | TheirAppender] = [
                OurAppender(engine),
                TheirAppender(engine, Path(folder)),
                TheirAppender(engine, Path(folder), per_track=True),
            ]
            samples: dict[str, dict[int, list[float]]] = {
                a.name: {b: [] for b in VERSUS_BATCHES} for a in pair
            }
            try:
                check_durability(name, pair)
                for batch in VERSUS_BATCHES:  # warm-up, not counted
                    for appender in pair:
                        appended_per_second(appender, stream[: VERSUS_EVENTS[batch] // 10], batch)
                for round_index in range(args.rounds):
                    for batch in VERSUS_BATCHES:
                        shift = round_index % len(pair)  # each goes first in turn
                        order = pair[shift:] + pair[:shift]
                        for appender in order:
                            events = stream[: VERSUS_EVENTS[batch]]
                            samples[appender.name][batch].append(
                                appended_per_second(appender, events, batch)
                            )
            finally:
                for appender in pair:
                    appender.close()
            by_backend[name] = {
                str(batch): versus_row({key: samples[key][batch] for key in samples})
                for batch in VERSUS_BATCHES
            }
    print(f"\nevents appended per second, median of {args.rounds} interleaved rounds;")
    print("ours/theirs: the ratio of the medians, then the lowest and highest round's ratio")
    print(
        f"{'backend':<10}{'batch':>6}{'ours':>9}{'eventsourcing':>15}{'ours/theirs':>22}"
        f"{'per track':>11}{'ours/theirs':>22}"
    )
    for name, _ in built:
        for batch in VERSUS_BATCHES:
            row = by_backend[name][str(batch)]
            ours = row.samples["ours"]
            one = ratio_range(ours, row.samples["eventsourcing"])
            per_track = ratio_range(ours, row.samples["eventsourcing per track"])
            print(
                f"{name:<10}{batch:>6}{row.ours_events_per_s:>9,.0f}"
                f"{row.eventsourcing_events_per_s:>15,.0f}"
                f"{row.ratio:>10.2f} ({one[0]:.2f}-{one[1]:.2f})"
                f"{row.eventsourcing_per_track_events_per_s:>11,.0f}"
                f"{row.ratio_per_track:>10.2f} ({per_track[0]:.2f}-{per_track[1]:.2f})"
            )
    results = VersusResult(
        rounds=args.rounds,
        events_per_measurement=VERSUS_EVENTS,
        event_json_bytes_mean=statistics.fmean(sizes),
        peer=peer,
        sqlite=by_backend.get("sqlite"),
        postgres=by_backend.get("postgres"),
    )
    write_results("store-versus", results)


def check_durability(backend: str, appenders: list[OurAppender | TheirAppender]) -> None:
    """Print each appender's durability settings; stop when they differ (no fair comparison)."""
    settings = {appender.name: appender.durability() for appender in appenders}
    for name, setting in settings.items():
        print(f"{backend}, {name}: {setting}")
    if len(set(settings.values())) != 1:
        sys.exit(f"{backend}: the appenders commit at different durability")


def versus_row(samples: dict[str, list[float]]) -> VersusRow:
    """The medians of one batch size's rounds, by appender, and ours against theirs."""
    ours = statistics.median(samples["ours"])
    theirs = statistics.median(samples["eventsourcing"])
    per_track = statistics.median(samples["eventsourcing per track"])
    return VersusRow(
        ours_events_per_s=ours,
        eventsourcing_events_per_s=theirs,
        ratio=ours / theirs,
        eventsourcing_per_track_events_per_s=per_track,
        ratio_per_track=ours / per_track,
        samples=samples,
    )


def bench_raw(args: argparse.Namespace) -> None:
    """Bytes per raw frame before and after the compact format, and per event."""
    from api_schema import BatchIn
    from bench.service_load import render_templates
    from codec.canonical import canonical_json
    from codec.observations import decode_batch
    from core.decide import decide
    from core.state import SceneState
    from service.store.raw_batches import ZSTD_LEVEL, decode_raw_batch, encode_raw_batch

    templates = render_templates(min(args.frames, 20))
    before, after, encode_ms, decode_ms, events_per_batch, event_bytes = [], [], [], [], [], []
    state = SceneState()
    for index in range(args.frames):
        raw = templates[index % len(templates)].body(f"raw-{index}", index / 5.0)
        body = BatchIn.model_validate_json(raw).model_dump(mode="json")
        canonical = canonical_json(body)
        t0 = time.perf_counter()
        stored = encode_raw_batch(body, "scn-bench")
        t1 = time.perf_counter()
        assert decode_raw_batch(stored) == canonical
        t2 = time.perf_counter()
        before.append(len(canonical))
        after.append(len(stored))
        encode_ms.append((t1 - t0) * 1e3)
        decode_ms.append((t2 - t1) * 1e3)
        events = decide(state, decode_batch(BatchIn.model_validate_json(canonical)))
        state = fold(state, events)
        events_per_batch.append(len(events))
        event_bytes += [len(orjson.dumps(event.details())) for event in events]
    steady = events_per_batch[len(events_per_batch) // 2 :]
    per_event = statistics.fmean(steady)
    results = RawResult(
        frames=args.frames,
        zstd_level=ZSTD_LEVEL,
        json_base64_bytes_per_frame=statistics.fmean(before),
        compact_bytes_per_frame=statistics.fmean(after),
        compact_max_bytes_per_frame=max(after),
        ratio=statistics.fmean(after) / statistics.fmean(before),
        encode_ms_median=statistics.median(encode_ms),
        decode_ms_median=statistics.median(decode_ms),
        events_per_frame_steady=per_event,
        compact_raw_bytes_per_event=statistics.fmean(after) / per_event,
        json_base64_raw_bytes_per_event=statistics.fmean(before) / per_event,
        event_details_bytes_mean=statistics.fmean(event_bytes),
        goal_bytes_per_frame=300_000,
    )
    print(
        f"raw batch per 640x480 frame: {results.json_base64_bytes_per_frame / 1e6:.3f} MB as "
        f"JSON with base64 depth -> {results.compact_bytes_per_frame / 1e6:.3f} MB compact "
        f"(x{results.ratio:.2f}; max {max(after) / 1e6:.3f} MB; goal 0.300 MB)"
    )
    print(
        f"encode {results.encode_ms_median:.2f} ms, decode {results.decode_ms_median:.2f} ms "
        "per frame (median)"
    )
    print(
        f"{per_event:.1f} events per frame (steady state): raw "
        f"{results.compact_raw_bytes_per_event / 1e3:.1f} kB per event compact "
        f"({results.json_base64_raw_bytes_per_event / 1e3:.1f} kB before); an event's "
        f"details are {results.event_details_bytes_mean:.0f} bytes of JSON"
    )
    write_results("store-raw", results)


def snapshot_storage(engine: sa.Engine) -> SnapshotStorage:
    """How many snapshots, and the bytes of their bodies."""
    with engine.connect() as connection:
        count, size = connection.execute(
            sa.select(
                sa.func.count(), sa.func.coalesce(sa.func.sum(sa.func.length(snapshots.c.body)), 0)
            )
        ).one()
    return SnapshotStorage(snapshots=int(count), snapshot_bytes=int(size))


def database_bytes(engine: sa.Engine) -> int:
    """Size of the database (SQLite file or PostgreSQL schema tables)."""
    with engine.connect() as connection:
        if engine.dialect.name == "sqlite":
            pages = connection.exec_driver_sql("PRAGMA page_count").scalar() or 0
            size = connection.exec_driver_sql("PRAGMA page_size").scalar() or 0
            return int(pages) * int(size)
        return int(
            connection.execute(
                sa.text(
                    "select sum(pg_total_relation_size(c.oid)) from pg_class c "
                    "join pg_namespace n on n.oid = c.relnamespace "
                    "where n.nspname = current_schema() and c.relkind = 'r'"
                )
            ).scalar()
            or 0
        )


def main(argv: list[str] | None = None) -> None:
    """Command line."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    append = commands.add_parser("append")
    append.add_argument("--events", type=int, default=50_000)
    append.add_argument("--batch", type=int, default=500)
    append.add_argument("--postgres", help="also measure on this PostgreSQL URL")
    as_of = commands.add_parser("as-of")
    as_of.add_argument("--events", type=int, default=1_000_000)
    as_of.add_argument(
        "--snapshot-interval",
        type=int,
        default=Settings.model_fields["snapshot_interval"].default,
        help="events between snapshots (default: the service's PBDAG_SNAPSHOT_INTERVAL default)",
    )
    as_of.add_argument("--queries", type=int, default=50)
    as_of.add_argument("--postgres", help="also measure on this PostgreSQL URL")
    versus = commands.add_parser("versus")
    versus.add_argument("--rounds", type=int, default=5)
    versus.add_argument("--postgres", help="also measure on this PostgreSQL URL")
    raw = commands.add_parser("raw")
    raw.add_argument("--frames", type=int, default=40)
    args = parser.parse_args(argv)
    handlers = {
        "append": bench_append,
        "as-of": bench_as_of,
        "versus": bench_versus,
        "raw": bench_raw,
    }
    handlers[args.command](args)


if __name__ == "__main__":
    main()
