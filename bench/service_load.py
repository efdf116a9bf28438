"""The end-to-end benchmark's load: 640x480 batches rendered once by the simulator, as body
templates a batch id and a timestamp are put into; and where one batch's time goes in one process."""

import json
import re
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bench.bench_decide import table_with_twenty_objects
from sim.camera import CameraModel, look_at
from sim.detector import detect, detect_fixtures
from sim.render import add_kinect_noise, render
from sim.wire import make_batch, make_frame
from sim.world import Box, World

# Placeholders in the pre-rendered bodies, replaced by each batch's own id and timestamp.
BATCH_MARK, FRAME_MARK, TIME_MARK = "@@BATCH@@", "@@FRAME@@", 987654321.25


# --- the load: pre-rendered bodies ---------------------------------------------------------


def bench_world() -> World:
    """A long table carrying 20 objects, with a counter and a shelf beside it (all fixtures)."""
    table, objects = table_with_twenty_objects()
    counter = Box("counter", "counter", (3.0, 4.1, 0.45), (1.2, 0.5, 0.9), kind="fixture")
    shelf = Box("shelf", "shelf", (5.0, 4.2, 0.6), (1.0, 0.4, 1.2), kind="fixture")
    return World(room_size=(8.0, 6.0, 2.6), fixtures=(table, counter, shelf), objects=objects)


@dataclass(frozen=True)
class BodyTemplate:
    """A rendered one-frame batch as JSON bytes, split around its batch id, frame id and time."""

    parts: tuple[bytes, ...]
    keys: tuple[str, ...]  # what goes between consecutive parts: "batch", "frame" or "time"
    objects: int
    fixtures: int

    def body(self, batch_id: str, timestamp: float) -> bytes:
        quoted = json.dumps(batch_id).encode()
        values = {"batch": quoted, "frame": quoted, "time": repr(float(timestamp)).encode()}
        pieces = [self.parts[0]]
        for key, part in zip(self.keys, self.parts[1:], strict=True):
            pieces += [values[key], part]
        return b"".join(pieces)


def split_template(text: str) -> tuple[tuple[bytes, ...], tuple[str, ...]]:
    """Split serialized JSON at its placeholders (the ids with their quotes)."""
    marks = {json.dumps(BATCH_MARK): "batch", json.dumps(FRAME_MARK): "frame"}
    marks[repr(TIME_MARK)] = "time"
    pattern = "|".join(re.escape(mark) for mark in marks)
    parts: list[bytes] = []
    keys: list[str] = []
    position = 0
    for match in re.finditer(pattern, text):
        parts.append(text[position : match.start()].encode())
        keys.append(marks[match.group(0)])
        position = match.end()
    parts.append(text[position:].encode())
    if sorted(keys) != ["batch", "frame", "time"]:
        raise ValueError(f"placeholders found: {keys}")
    return tuple(parts), tuple(keys)


def render_templates(count: int, seed: int = 0) -> list[BodyTemplate]:
    """`count` consecutive views of the table (the camera sways 20 cm side to side)."""
    world = bench_world()
    camera = CameraModel()
    rng = np.random.default_rng(seed)
    templates = []
    for index in range(count):
        sway = 0.1 * np.sin(2 * np.pi * index / count)
        pose = look_at((4.0 + sway, 1.2, 1.6), (4.0 + sway, 3.0, 0.75))
        view = render(world, camera, pose)
        fixtures = detect_fixtures(view, world, rng, min_visible_pixels=400)
        objects = detect(
            view, world, rng, min_visible_pixels=50, boundary_leak_px=1, embedding_noise=0.05
        )
        depth = add_kinect_noise(view.depth, rng).astype(np.float32)
        frame = make_frame(FRAME_MARK, TIME_MARK, camera, pose, depth, [*fixtures, *objects])
        text = json.dumps(make_batch(BATCH_MARK, [frame]), separators=(",", ":"))
        parts, keys = split_template(text)
        templates.append(BodyTemplate(parts, keys, len(objects), len(fixtures)))
    return templates


# --- where a batch's time goes, in one process --------------------------------------------


def stage_breakdown(templates: Sequence[BodyTemplate], count: int, rate: float) -> dict[str, float]:
    """Median milliseconds of each CPU stage of one batch, in this process on one thread (no
    HTTP, no database): what the API does (parse, validate and decode, canonical JSON and its
    hash) and what the worker does (parse and decode again, decide, fold into the state); the
    batches' timestamps are `rate` per second apart."""
    import hashlib

    from api_schema import BatchIn
    from codec.canonical import canonical_json
    from codec.observations import decode_batch
    from core.decide import decide
    from core.evolve import fold
    from core.state import SceneState

    stages: dict[str, list[float]] = {
        "parse_validate": [],
        "decode": [],
        "canonical_json_sha256": [],
        "decide": [],
        "fold": [],
    }
    state = SceneState()
    for index in range(count):
        body = templates[index % len(templates)].body(f"profile-{index}", index / rate)
        t0 = time.perf_counter()
        wire = BatchIn.model_validate_json(body)
        t1 = time.perf_counter()
        batch = decode_batch(wire)
        t2 = time.perf_counter()
        hashlib.sha256(canonical_json(wire.model_dump(mode="json"))).hexdigest()
        t3 = time.perf_counter()
        events = decide(state, batch)
        t4 = time.perf_counter()
        state = fold(state, events)
        t5 = time.perf_counter()
        for name, seconds in zip(
            stages, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True
        ):
            stages[name].append(seconds * 1e3)
    # The first batches create the tracks; the steady state is what a long run sees.
    return {name: round(statistics.median(v[count // 2 :]), 1) for name, v in stages.items()}
