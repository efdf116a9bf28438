"""Fixtures of the ingest tests: a real `pbdag serve` on a free loopback port (temporary SQLite
database and data directory), and the recordings written from the real kitchen frames."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.e2e.fault_run import free_port, wait_healthy
from tests.ingest.recordings import write_bag, write_folder, write_label_map

FRAMES = 20
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def service_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The URL of a `pbdag serve` (with its worker) that the ingest tests share."""
    data = tmp_path_factory.mktemp("service")
    port = free_port()
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(data),
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",  # the ingest runs on 127.0.0.1
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",  # --wait polls batch statuses
    }
    env.pop("PBDAG_DATABASE_URL", None)  # SQLite in the data directory
    with (data / "service.log").open("ab") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve", "--port", str(port)],
            env=env,
            cwd=REPO,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url)
        yield url
    finally:
        process.terminate()
        process.wait(timeout=30)


@dataclass(frozen=True)
class Recordings:
    """What the tests ingest: the folder (with `masks/`), the bags and the label map."""

    folder: Path
    bag: Path
    gappy_bag: Path  # frame 7 has no /tf nor /odom, frame 12 no label image
    float_bag: Path  # 32FC1 depth in metres, NaN where there is no measurement
    labels: Path


@pytest.fixture(scope="session")
def recordings(real_kitchen: Path, tmp_path_factory: pytest.TempPathFactory) -> Recordings:
    """The recordings, written once from the first 20 real frames."""
    root = tmp_path_factory.mktemp("recordings")
    return Recordings(
        folder=write_folder(real_kitchen, root / "kitchen", FRAMES),
        bag=write_bag(real_kitchen, root / "kitchen_bag", FRAMES),
        gappy_bag=write_bag(
            real_kitchen,
            root / "gappy_bag",
            FRAMES,
            without_tf=frozenset({7}),
            without_labels=frozenset({12}),
        ),
        float_bag=write_bag(real_kitchen, root / "float_bag", 5, float_depth=True),
        labels=write_label_map(root / "labels.json"),
    )
