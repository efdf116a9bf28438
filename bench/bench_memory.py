"""Benchmark: peak memory of the API and of a worker for the largest batches the limits accept.

    python -m bench.bench_memory [--budget-mb 1024]

Each case is one batch at the edge of the default limits (PBDAG_MAX_*): the body is as large as
PBDAG_MAX_BODY_BYTES allows and every other limit is reached where the case says. A fresh
`pbdag serve --no-worker` accepts it and a fresh `pbdag worker --drain` processes it (both on a
temporary SQLite file); the peak resident set size of each process (its ru_maxrss, imports
included) is printed beside the documented budget and written to bench/results/memory.json.
"""

from __future__ import annotations

import argparse
import base64
import io
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from PIL import Image
from pycocotools import mask as coco_mask
from pydantic import TypeAdapter

from bench.perf_common import write_results
from bench.records import MemoryCase, MemoryResult
from core.params import MAX_CLASS_SCORE_CELLS, Params
from service.settings import Settings

PBDAG = [sys.executable, "-m", "service.cli"]
DEFAULTS = Settings()
WIDTH, HEIGHT = 1920, 1250  # the most pixels PBDAG_MAX_IMAGE_PIXELS admits at 16:10
POSE = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]


def depth_png(depth_mm: np.ndarray) -> str:
    buffer = io.BytesIO()
    Image.fromarray(depth_mm.astype(np.uint16)).save(buffer, format="PNG", compress_level=1)
    return base64.b64encode(buffer.getvalue()).decode()


def rle(mask: np.ndarray) -> dict[str, Any]:
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


def frame(
    index: int,
    width: int,
    height: int,
    depth_mm: np.ndarray,
    detections: list[dict[str, Any]],
) -> dict[str, Any]:
    return {
        "frame_id": f"f{index}",
        "timestamp": float(index),
        "intrinsics": {
            "width": width,
            "height": height,
            "fx": 1000.0,
            "fy": 1000.0,
            "cx": width / 2,
            "cy": height / 2,
        },
        "pose": POSE,
        "depth": {"encoding": "png16", "scale": 0.001, "data": depth_png(depth_mm)},
        "detections": detections,
    }


def noise_frames() -> list[dict[str, Any]]:
    """Incompressible depth at the largest image size: as many frames as the body limit takes."""
    rng = np.random.default_rng(0)
    half = np.zeros((HEIGHT, WIDTH), dtype=bool)
    half[:, : WIDTH // 2] = True
    detections = [{"label": "mug", "score": 0.9, "mask": rle(half)} for _ in range(4)]
    frames: list[dict[str, Any]] = []
    size = 0
    while len(frames) < DEFAULTS.max_frames_per_batch:
        depth = rng.integers(300, 6000, size=(HEIGHT, WIDTH))
        candidate = frame(len(frames), WIDTH, HEIGHT, depth, detections)
        size += len(candidate["depth"]["data"]) + 2000
        if size > 0.95 * DEFAULTS.max_body_bytes:
            break
        frames.append(candidate)
    return frames


def many_objects() -> list[dict[str, Any]]:
    """One largest frame with the most detections, masks covering the most pixels a batch may,
    each with a long embedding and the most class scores, up to the body limit."""
    rng = np.random.default_rng(1)
    depth = np.full((HEIGHT, WIDTH), 2000)
    # Together the masks cover as many pixels as PBDAG_MAX_MASK_PIXELS_PER_BATCH allows.
    side = int((DEFAULTS.max_mask_pixels_per_batch / DEFAULTS.max_detections_per_frame) ** 0.5)
    masks = [np.zeros((HEIGHT, WIDTH), dtype=bool) for _ in range(8)]
    for k, mask in enumerate(masks):
        mask[k * 100 : k * 100 + side, k * 150 : k * 150 + side] = True
    encoded = [rle(mask) for mask in masks]
    scores = {f"class{i}": 0.01 for i in range(DEFAULTS.max_class_scores)}
    per_detection = DEFAULTS.max_body_bytes // DEFAULTS.max_detections_per_frame
    length = min(DEFAULTS.max_embedding_length, per_detection // 22)  # ~21 bytes per float
    detections = [
        {
            "label": f"thing{k % 16}",
            "score": 0.9,
            "mask": encoded[k % len(encoded)],
            "embedding": [float(v) for v in rng.normal(size=length)],
            "class_scores": scores,
        }
        for k in range(DEFAULTS.max_detections_per_frame)
    ]
    return [frame(0, WIDTH, HEIGHT, depth, detections)]


def many_fixtures() -> list[dict[str, Any]]:
    """Full-frame fixture masks over noise depth, as many as the batch's mask pixels allow:
    each would scatter into 150,000 voxels."""
    rng = np.random.default_rng(2)
    depth = rng.integers(300, 6000, size=(HEIGHT, WIDTH))
    full = rle(np.ones((HEIGHT, WIDTH), dtype=bool))
    count = min(
        DEFAULTS.max_detections_per_frame, DEFAULTS.max_mask_pixels_per_batch // (HEIGHT * WIDTH)
    )
    detections = [
        {"label": "table", "score": 0.9, "kind": "fixture", "mask": full} for _ in range(count)
    ]
    return [frame(0, WIDTH, HEIGHT, depth, detections)]


def many_frames() -> list[dict[str, Any]]:
    """The most frames, each VGA with the most small detections."""
    rng = np.random.default_rng(3)
    frames = []
    for index in range(DEFAULTS.max_frames_per_batch):
        depth = rng.integers(1500, 2500, size=(480, 640))
        detections = []
        for k in range(DEFAULTS.max_detections_per_frame):
            mask = np.zeros((480, 640), dtype=bool)
            row, col = divmod(k, 16)
            mask[row * 30 : row * 30 + 25, col * 40 : col * 40 + 35] = True
            detections.append({"label": f"thing{k % 10}", "score": 0.8, "mask": rle(mask)})
        frames.append(frame(index, 640, 480, depth, detections))
    return frames


# The budgets a scene's params set, each raised to the end of its range (the finest voxel and
# stride at the low end): the most work a write token can ask of a worker per batch.
WORK_BUDGETS = {
    "ProposalParams": {"max_mask_samples": "maximum"},
    "FixtureParams": {
        "max_voxels_per_batch": "maximum",
        "max_points_per_batch": "maximum",
        "mask_pixel_stride": "minimum",
        "voxel_size_m": "minimum",
    },
    "VisibilityParams": {"max_range_m": "maximum"},
    "OccupancyParams": {"max_range_m": "maximum", "pixel_stride": "minimum"},
}
SECTIONS = {
    "ProposalParams": "proposal",
    "FixtureParams": "fixtures",
    "VisibilityParams": "visibility",
    "OccupancyParams": "occupancy",
}


def most_work_params() -> dict[str, Any]:
    """Scene params with every work budget at the end of its documented range, and the
    longest taxonomy (read from the params' own schema, so the case follows the ranges)."""
    schema = TypeAdapter(Params).json_schema()["$defs"]
    params: dict[str, Any] = {}
    for model, fields in WORK_BUDGETS.items():
        properties = schema[model]["properties"]
        params[SECTIONS[model]] = {
            name: properties[name].get(end, properties[name].get(f"exclusive{end.title()}"))
            for name, end in fields.items()
        }
    labels = schema["FixtureParams"]["properties"]["taxonomy"]["maxItems"]
    params["fixtures"]["taxonomy"] = [f"fixture{i}" for i in range(labels)]
    # A batch's voxels times the classes are bounded together (see FixtureParams).
    voxels = params["fixtures"]["max_voxels_per_batch"]
    params["fixtures"]["max_voxels_per_batch"] = min(voxels, MAX_CLASS_SCORE_CELLS // labels)
    params["fixtures"]["inspection_taxonomy"] = []
    return params


def ramp_fixture_frames() -> list[dict[str, Any]]:
    """The most frames of the largest image, each with one full-frame fixture mask scored for
    every class: depth ramps along each row to the furthest range the params admit (identical
    rows compress to a few KB, yet every pixel lands in a voxel of its own)."""
    depth = np.tile(np.linspace(300, 65000, WIDTH), (HEIGHT, 1))
    full = rle(np.ones((HEIGHT, WIDTH), dtype=bool))
    taxonomy = most_work_params()["fixtures"]["taxonomy"]
    scores = {label: 0.5 for label in taxonomy[: DEFAULTS.max_class_scores]}
    detection = {"label": taxonomy[0], "score": 0.9, "kind": "fixture", "mask": full}
    detection["class_scores"] = scores
    return [
        frame(index, WIDTH, HEIGHT, depth, [detection])
        for index in range(DEFAULTS.max_frames_per_batch)
    ]


# Each case: the batch, and the scene params it is posted under (None: the defaults).
CASES: dict[str, tuple[Callable[[], list[dict[str, Any]]], Callable[[], dict[str, Any]] | None]] = {
    "largest depth images": (noise_frames, None),
    "most detections with long embeddings": (many_objects, None),
    "most fixture masks over noise depth": (many_fixtures, None),
    "most frames with most detections": (many_frames, None),
    "fixture masks under the most-work params": (ramp_fixture_frames, most_work_params),
}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def peak_mb(process: subprocess.Popen[bytes]) -> float:
    """The ru_maxrss of a finished child, in MB."""
    _pid, _status, usage = os.wait4(process.pid, 0)
    return usage.ru_maxrss / 1024


def run_case(
    name: str,
    make: Callable[[], list[dict[str, Any]]],
    root: Path,
    params: dict[str, Any] | None = None,
) -> MemoryCase:
    """Serve, post the batch (into a scene with `params`), stop the API; drain with a worker;
    peak memory of both."""
    body: dict[str, Any] = {"batch_id": "largest", "frames": make()}
    content = httpx.Request("POST", "http://x", json=body).content
    data = root / name.replace(" ", "-")
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(data),
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
    }
    env.pop("PBDAG_DATABASE_URL", None)
    port = free_port()
    api = subprocess.Popen(
        [*PBDAG, "serve", "--no-worker", "--port", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(200):
            try:
                httpx.get(f"{url}/healthz", timeout=1.0)
                break
            except httpx.TransportError:
                time.sleep(0.1)
        created = httpx.post(f"{url}/v1/scenes", json={"name": "memory", "params": params or {}})
        if created.status_code != 201:
            raise RuntimeError(f"{name}: scene refused {created.status_code} {created.text[:300]}")
        scene = created.json()["id"]
        started = time.perf_counter()
        response = httpx.post(
            f"{url}/v1/scenes/{scene}/batches",
            content=content,
            headers={"content-type": "application/json"},
            timeout=300,
        )
        accept_seconds = time.perf_counter() - started
        if response.status_code != 202:
            raise RuntimeError(f"{name}: {response.status_code} {response.text[:300]}")
    finally:
        api.terminate()
    api_mb = peak_mb(api)
    started = time.perf_counter()
    worker = subprocess.Popen(
        [*PBDAG, "worker", "--drain"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    worker_mb = peak_mb(worker)
    work_seconds = time.perf_counter() - started
    status = subprocess.run(
        [sys.executable, "-c", _STATUS, str(data), scene],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    return MemoryCase(
        body_mb=len(content) / 2**20,
        frames=len(body["frames"]),
        detections=sum(len(f["detections"]) for f in body["frames"]),
        api_peak_mb=api_mb,
        worker_peak_mb=worker_mb,
        accept_seconds=accept_seconds,
        work_seconds=work_seconds,
        batch_status=status,
    )


_STATUS = """
import sys
from pathlib import Path
from service.bootstrap import build_container
from service.settings import Settings
container = build_container(Settings(data_dir=Path(sys.argv[1])))
print(container.queue.get(sys.argv[2], "largest").status)
"""


def main(argv: list[str] | None = None) -> None:
    """Print each case's peaks against the budget; write bench/results/memory.json."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget-mb", type=float, default=1024.0)
    args = parser.parse_args(argv)
    cases: dict[str, MemoryCase] = {}
    with tempfile.TemporaryDirectory(prefix="pbdag-memory-") as temp:
        for name, (make, params) in CASES.items():
            print(f"{name}: posting ...", flush=True)
            case = cases[name] = run_case(name, make, Path(temp), params() if params else None)
            within = max(case.api_peak_mb, case.worker_peak_mb) <= args.budget_mb
            print(
                f"{name:>38}: {case.body_mb:5.1f} MB body, {case.frames} frames, "
                f"{case.detections} detections -> API {case.api_peak_mb:.0f} MB, worker "
                f"{case.worker_peak_mb:.0f} MB ({case.batch_status}, "
                f"{case.work_seconds:.1f} s); budget {args.budget_mb:.0f} MB "
                f"{'held' if within else 'EXCEEDED'}"
            )
    write_results("memory", MemoryResult(budget_mb=args.budget_mb, cases=cases))


if __name__ == "__main__":
    main()
