"""The per-batch cost of the blob backends, side by side: the folder against PostgreSQL's table.

    python -m bench.bench_blobs --postgres URL [--rounds 5] [--batches 30]

What the API does per batch (`BatchQueue.submit`: the admission check, the blob, the queue row,
one commit) and what a worker does first (`get` the blob), for rendered 640x480 batches as the
API stores them (the compact raw format: one frame about 0.32 MB, two frames about 0.64 MB) and
as canonical JSON (the format before it, which older data dirs hold: two frames, 0.87 MB).
Every blob is distinct. Backends, interleaved round by round, each round on a fresh scene:

- `sqlite+folder`: the SQLite file and the folder (the single-host default);
- `postgres+folder`: the queue in PostgreSQL, the blobs in a folder (PBDAG_BLOB_BACKEND=folder);
- `postgres+table`: the blobs in PostgreSQL, in the queue's transaction (the default there);
- `postgres+table-pglz`: the same, with the server's default TOAST compression of the column
  (the migration stores it out of line, uncompressed; this shows why).

Figures are medians over every batch of every round; printed, and written to
bench/results/blobs.json. The folder is a temporary directory on this machine's disk.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from bench.perf_common import write_results
from bench.records import BlobBackendFigures, BlobBody, BlobsResult
from bench.service_fleet import fresh_schema
from core.params import Params
from service.store.blobs import BlobStore, FileBlobStore, PgBlobStore
from service.store.engine import make_engine, migrate, write_transaction
from service.store.event_log import EventLog
from service.store.queue import BatchQueue
from service.store.queue_records import Admission

UNBOUNDED = Admission(max_queued=10**9, max_blob_bytes=10**15, retry_after_seconds=1)


@dataclass
class Backend:
    """One way to store a batch: its queue (on an engine) and its blob store."""

    name: str
    engine: sa.Engine
    blobs: BlobStore
    schema: str | None = None

    @property
    def queue(self) -> BatchQueue:
        return BatchQueue(self.engine, self.blobs)


def canonical_bodies(count: int, frames: int, compact: bool) -> Iterator[bytes]:
    """`count` distinct blobs as the API stores them: rendered 640x480 batches of `frames`
    frames (20 object masks, 3 fixture masks and a depth image each), validated, in the compact
    raw format (binary depth, zstandard) or as canonical JSON (the format before it)."""
    from api_schema import BatchIn
    from bench.service_load import render_templates
    from codec.canonical import canonical_json
    from service.store.raw_batches import encode_raw_batch

    templates = render_templates(4)
    for index in range(count):
        batch_id = f"bench-{uuid.uuid4().hex}"
        body: dict[str, Any] = {"batch_id": batch_id, "frames": []}
        for offset in range(frames):
            template = templates[(index + offset) % len(templates)]
            frame = json.loads(template.body(batch_id, index + offset / 10))["frames"][0]
            frame["frame_id"] = f"{batch_id}-{offset}"
            body["frames"].append(frame)
        wire = BatchIn.model_validate(body).model_dump(mode="json")
        yield encode_raw_batch(wire, "scn-bench") if compact else canonical_json(wire)


@contextmanager
def backends(postgres_url: str, folder: Path) -> Iterator[list[Backend]]:
    """The four backends, each on its own migrated SQLite file or PostgreSQL schema."""
    with ExitStack() as stack:
        built = [
            Backend(
                "sqlite+folder",
                make_engine(f"sqlite:///{folder / 'bench.db'}"),
                FileBlobStore(folder / "sqlite-blobs"),
            )
        ]
        for name in ("postgres+folder", "postgres+table", "postgres+table-pglz"):
            schema = stack.enter_context(fresh_schema(postgres_url, "pbdag_blob_bench"))
            engine = make_engine(postgres_url, connect_args={"options": f"-csearch_path={schema}"})
            blobs: BlobStore = (
                FileBlobStore(folder / f"{name}-blobs")
                if name.endswith("folder")
                else PgBlobStore(engine)
            )
            built.append(Backend(name, engine, blobs, schema))
        for backend in built:
            migrate(backend.engine)
            stack.callback(backend.engine.dispose)
        with write_transaction(built[-1].engine) as connection:
            connection.exec_driver_sql(
                "ALTER TABLE blobs ALTER COLUMN content SET STORAGE EXTENDED"
            )
        yield built


def new_scene(backend: Backend) -> str:
    log = EventLog(backend.engine)
    with write_transaction(backend.engine) as connection:
        return log.insert_scene(connection, "bench", Params())[0].id


def timed(action: Callable[..., Any], *args: Any) -> float:
    """Milliseconds `action(*args)` took."""
    started = time.perf_counter()
    action(*args)
    return (time.perf_counter() - started) * 1e3


def one_round(backend: Backend, blobs: list[bytes], samples: dict[str, list[float]]) -> None:
    """Queue every blob (timed), then read every blob back (timed) and check it."""
    scene_id = new_scene(backend)
    queue = backend.queue
    keys = []
    for index, blob in enumerate(blobs):
        sha = hashlib.sha256(blob).hexdigest()
        took = timed(queue.submit, scene_id, f"b{index}", sha, blob, 1, UNBOUNDED)
        samples["put_enqueue_ms"].append(took)
        keys.append(sha)
    for key, blob in zip(keys, blobs, strict=True):
        started = time.perf_counter()
        got = backend.blobs.get(key)
        samples["get_ms"].append((time.perf_counter() - started) * 1e3)
        if got != blob:
            raise RuntimeError(f"{backend.name}: blob {key} came back altered")


def stored_bytes(backend: Backend, folder: Path) -> int:
    """Bytes the backend's blobs take on disk (the table with its TOAST, or the files)."""
    if isinstance(backend.blobs, FileBlobStore):
        return sum(path.stat().st_blocks * 512 for path in backend.blobs.root.rglob("*"))
    with backend.engine.connect() as connection:
        query = sa.text("SELECT pg_total_relation_size('blobs')")
        return int(connection.execute(query).scalar_one())


def bench(postgres_url: str, rounds: int, batches: int) -> BlobsResult:
    """Both body sizes on every backend; figures per backend and the ratios to the folder."""
    count = batches * rounds
    print(f"rendering {count} distinct 640x480 batch bodies of 1 and 2 frames ...", flush=True)
    sizes = {
        "json-2-frames": list(canonical_bodies(count, 2, compact=False)),
        "compact-2-frames": list(canonical_bodies(count, 2, compact=True)),
        "compact-1-frame": list(canonical_bodies(count, 1, compact=True)),
    }
    bodies: dict[str, BlobBody] = {}
    for size_name, blobs in sizes.items():
        with (
            tempfile.TemporaryDirectory(prefix="pbdag-blob-bench-") as temp,
            backends(postgres_url, Path(temp)) as built,
        ):
            samples: dict[str, dict[str, list[float]]] = {
                b.name: {"put_enqueue_ms": [], "get_ms": []} for b in built
            }
            for round_index in range(rounds):
                chunk = blobs[round_index * batches : (round_index + 1) * batches]
                order = built if round_index % 2 == 0 else list(reversed(built))
                for backend in order:
                    one_round(backend, chunk, samples[backend.name])
            figures: dict[str, BlobBackendFigures] = {}
            for backend in built:
                put = samples[backend.name]["put_enqueue_ms"]
                get = samples[backend.name]["get_ms"]
                figures[backend.name] = BlobBackendFigures(
                    put_enqueue_ms_median=round(statistics.median(put), 2),
                    put_enqueue_ms_p90=round(statistics.quantiles(put, n=10)[-1], 2),
                    get_ms_median=round(statistics.median(get), 2),
                    get_ms_p90=round(statistics.quantiles(get, n=10)[-1], 2),
                    disk_bytes_per_blob=round(stored_bytes(backend, Path(temp)) / len(blobs)),
                )
            base = figures["postgres+folder"]
            for name in ("postgres+table", "postgres+table-pglz"):
                row = figures[name]
                figures[name] = replace(
                    row,
                    put_enqueue_vs_folder=round(
                        row.put_enqueue_ms_median / base.put_enqueue_ms_median, 2
                    ),
                    get_vs_folder=round(row.get_ms_median / base.get_ms_median, 2),
                )
            mean_bytes = round(statistics.mean(len(b) for b in blobs))
            bodies[size_name] = BlobBody(mean_blob_bytes=mean_bytes, backends=figures)
    return BlobsResult(rounds=rounds, batches_per_round=batches, bodies=bodies)


def print_table(results: BlobsResult) -> None:
    print(
        f"\nper batch, medians (p90) over {results.rounds} rounds x "
        f"{results.batches_per_round} batches; ratios: PostgreSQL table / folder, "
        "both with the queue in PostgreSQL"
    )
    print(
        f"{'body':>16} {'backend':>20} {'put+enqueue ms':>18} {'get ms':>16} "
        f"{'disk KB':>8} {'ratio put':>9} {'ratio get':>9}"
    )
    for size_name, body in results.bodies.items():
        label = f"{size_name} {body.mean_blob_bytes / 1e6:.2f} MB"
        for name, row in body.backends.items():
            put_ratio = "" if row.put_enqueue_vs_folder is None else row.put_enqueue_vs_folder
            get_ratio = "" if row.get_vs_folder is None else row.get_vs_folder
            print(
                f"{label:>16} {name:>20} "
                f"{row.put_enqueue_ms_median:>8.2f} ({row.put_enqueue_ms_p90:>6.2f}) "
                f"{row.get_ms_median:>7.2f} ({row.get_ms_p90:>6.2f}) "
                f"{row.disk_bytes_per_blob / 1024:>8.0f} {put_ratio:>9} {get_ratio:>9}"
            )


def main(argv: list[str] | None = None) -> None:
    """Command line."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--postgres", required=True, help="PostgreSQL URL (a schema is made)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--batches", type=int, default=30, help="batches per round")
    args = parser.parse_args(argv)
    results = bench(args.postgres, args.rounds, args.batches)
    print_table(results)
    write_results("blobs", results)


if __name__ == "__main__":
    main()
