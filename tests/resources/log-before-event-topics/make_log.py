"""Write a golden log that holds every event class, as the service stores it (see README.md).

    .venv/bin/python tests/resources/log-before-event-topics/make_log.py OUT_FOLDER

Four scenes go through the HTTP API and the worker, on a SQLite file: a closed-loop rollout
with plans and inspections, a kitchen with a verdict and a frozen baseline, a session from that
baseline with a batch that dies, and a carried mug that takes its identity back. The rows of
every table a rebuild reads or compares are then dumped exactly as stored.
"""

from __future__ import annotations

import argparse
import base64
import copy
import gzip
import hashlib
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import orjson
import sqlalchemy as sa

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))

from api_schema import BaselineRef, BatchIn, VerdictIn  # noqa: E402
from core.observation import Batch  # noqa: E402
from pbdag_client import Client  # noqa: E402
from pbdag_client.encoding import build_batch, build_frame, detection  # noqa: E402
from service.app import create_app  # noqa: E402
from service.bootstrap import Container, build_container  # noqa: E402
from service.settings import Settings  # noqa: E402
from service.store.tables import baselines, batches, events, scenes, snapshots, tracks  # noqa: E402
from service.worker import Worker  # noqa: E402
from sim.memories import ServiceMemory  # noqa: E402
from sim.rollout import rollout  # noqa: E402
from sim.scenario import load_scenario, scenario_from_dict  # noqa: E402
from sim.stream import iter_frames, iter_wire_batches  # noqa: E402
from tests.clients import local_pbdag_client  # noqa: E402
from tests.core import carried_mugs as carried  # noqa: E402
from tests.core.scenes import scene_batch  # noqa: E402
from tests.evaluation.test_active import SMALL  # noqa: E402

# The kitchen of `make demo` through a 320 x 240 camera, shortened to 60 frames (its story kept).
KITCHEN = ROOT / "sim" / "scenarios" / "demo.yaml"
# Every 8th pixel of a fixture mask, not every 4th: a quarter of the voxel evidence to store.
PARAMS = {"fixtures": {"mask_pixel_stride": 8}}
SMALL_CAMERA = {"width": 320, "height": 240, "fx": 262.5, "fy": 262.5, "cx": 159.5, "cy": 119.5}


def settings(folder: Path, snapshot_interval: int, max_attempts: int = 3) -> Settings:
    return Settings(
        database_url=f"sqlite:///{folder / 'pbdag.db'}",
        data_dir=folder / "data",
        snapshot_interval=snapshot_interval,
        max_attempts=max_attempts,
        allow_anonymous_local=True,
    )


@contextmanager
def service(folder: Path, snapshot_interval: int) -> Iterator[Client]:
    """The API with its worker on the one database; snapshots every `snapshot_interval` events
    (a snapshot of a large voxel map is most of a scene's bytes: the big scenes take none)."""
    container = build_container(settings(folder, snapshot_interval))
    with local_pbdag_client(create_app(container, run_worker=True)) as client:
        yield client
    container.engine.dispose()


def wire(batch: Batch) -> BatchIn:
    """A core batch of the tests' analytic camera as the client sends it (f32 depth: exact)."""
    frames = [
        build_frame(
            frame.frame_id,
            frame.timestamp,
            frame.depth,
            frame.intrinsics.__dict__,
            frame.pose,
            [
                detection(d.label, d.score, d.mask.to_array(), kind=d.kind, embedding=d.embedding)
                for d in frame.detections
            ],
            depth_encoding="f32",
        )
        for frame in batch.frames
    ]
    return build_batch(batch.batch_id, frames)


def carried_mug_batches() -> Iterator[Batch]:
    """tests/core/carried_mugs.py's carried mug: seen elsewhere, then its place empty."""
    both = {"mug_1": carried.A, "mug_2": carried.B}
    for i in range(3):
        yield scene_batch(f"b{i}", carried.TWO_MUGS, embeddings=both, t=float(i))
    yield scene_batch(
        "there",
        {"mug_1": carried.ELSEWHERE},
        pose=carried.TURNED,
        embeddings={"mug_1": carried.SAME_AS_A},
        t=3.0,
    )
    for i in range(2):
        yield scene_batch(f"e{i}", carried.MUG_2_ALONE, embeddings={"mug_2": carried.B}, t=4.0 + i)


def stream(client: Client, scene_id: str, seed: int, frames: int) -> None:
    """The kitchen's wire batches for `seed`, each waited for."""
    scenario = load_scenario(KITCHEN, {"camera": SMALL_CAMERA}, frames=frames)
    for _last, body in iter_wire_batches(scenario, seed, iter_frames(scenario, seed)):
        batch = BatchIn.model_validate(body)
        client.post_batch(scene_id, batch)
        client.wait_for_batch(scene_id, batch.batch_id, timeout=300.0)


def live_scenes(folder: Path) -> list[str]:
    """Scenes 0 to 3 through the API with its worker (the dead batch comes afterwards)."""
    with service(folder, snapshot_interval=50) as client:
        active = ServiceMemory(client, "active-small", PARAMS)
        rollout(scenario_from_dict(copy.deepcopy(SMALL)), 7, active, via_service=True)
    with service(folder, snapshot_interval=0) as client:
        kitchen = client.create_scene("kitchen", params=PARAMS).id
        stream(client, kitchen, 6, 60)
        pending = client.verifications(kitchen)[0]
        label = max(pending.candidates.items(), key=lambda item: item[1])[0]
        verdict = VerdictIn(verdict="confirm", label=label, source="golden-log")
        client.post_verdict(kitchen, pending.track_id, verdict)
        client.freeze_baseline(kitchen)
        session = client.create_scene(
            "session", params=PARAMS, baseline=BaselineRef(scene_id=kitchen, version=1)
        ).id
        stream(client, session, 7, 16)
    with service(folder, snapshot_interval=4) as client:
        mug = client.create_scene("carried mug").id
        for batch in carried_mug_batches():
            client.post_batch(mug, wire(batch))
            client.wait_for_batch(mug, batch.batch_id)
    return [active.scene_id, kitchen, session, mug]


def dead_batch(folder: Path, session: str) -> None:
    """A batch whose raw payload vanished before the worker claimed it: parked as dead and
    recorded in the log (`batch_skipped`); the batch after it applies."""
    container = build_container(settings(folder, 0, max_attempts=1))
    scenario = load_scenario(KITCHEN, {"camera": SMALL_CAMERA}, frames=30)
    bodies = [body for _last, body in iter_wire_batches(scenario, 11, iter_frames(scenario, 11))]
    with local_pbdag_client(create_app(container)) as client:
        for body in bodies[:2]:
            client.post_batch(session, BatchIn.model_validate(body))
    with container.engine.connect() as connection:
        key = connection.execute(
            sa.select(batches.c.blob_key).where(batches.c.batch_id == bodies[0]["batch_id"])
        ).scalar_one()
    container.blobs.delete(key)
    Worker(container).drain()
    container.engine.dispose()


def digested(state: dict[str, Any]) -> dict[str, Any]:
    """The state's JSON with its voxel map (most of its bytes) as a sha256 of its JSON."""
    voxels = orjson.dumps(state["voxels"])
    return {**state, "voxels": {"sha256": hashlib.sha256(voxels).hexdigest()}}


def plain(row: sa.Row[Any]) -> dict[str, Any]:
    """A row as JSON-able values under plain str keys (bytes as base64)."""
    return {
        str(key): base64.b64encode(value).decode() if isinstance(value, bytes) else value
        for key, value in row._mapping.items()
    }


def dump(container: Container, scene_ids: list[str], out: Path) -> None:
    """events.jsonl.gz (rows as stored), tables.json.gz (the other rows), states.json.gz."""
    index = {scene_id: number for number, scene_id in enumerate(scene_ids)}
    with container.engine.connect() as connection:
        rows = connection.execute(sa.select(events).order_by(events.c.scene_id, events.c.seq))
        lines = sorted(
            ({"scene": index[row.scene_id], **plain(row)} for row in rows),
            key=lambda row: (row["scene"], row["seq"]),
        )
        tables: dict[str, list[dict[str, Any]]] = {}
        for table in (scenes, tracks, baselines, snapshots):
            tables[str(table.name)] = [plain(row) for row in connection.execute(sa.select(table))]
    events_text = b"".join(orjson.dumps(row) + b"\n" for row in lines)
    (out / "events.jsonl.gz").write_bytes(gzip.compress(events_text, mtime=0))
    (out / "tables.json.gz").write_bytes(gzip.compress(orjson.dumps(tables), mtime=0))
    states = {
        str(index[scene_id]): digested(container.log.replay(scene_id).to_dict())
        for scene_id in scene_ids
    }
    (out / "states.json.gz").write_bytes(gzip.compress(orjson.dumps(states), mtime=0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out", type=Path)
    out = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        scene_ids = live_scenes(folder)
        dead_batch(folder, scene_ids[2])
        container = build_container(settings(folder, 0))
        dump(container, scene_ids, out)
        container.engine.dispose()


if __name__ == "__main__":
    main()
