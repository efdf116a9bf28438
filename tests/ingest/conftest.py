"""Fixtures of the ingest tests: a real `pbdag serve` on a free loopback port (temporary SQLite
database and data directory), and the recordings written from the real kitchen frames."""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.e2e.fault_run import free_port, wait_healthy
from tests.eval_extra import skip_modules_without_ingest_extra as pytest_pycollect_makemodule

__all__ = ["pytest_pycollect_makemodule"]

FRAMES = 20
REPO = Path(__file__).resolve().parents[2]


@dataclass
class Service:
    """A running `pbdag serve`: its URL, and a way to add a `pbdag worker` beside it."""

    url: str
    env: dict[str, str]
    log: Path
    processes: list[subprocess.Popen[bytes]]

    def start(self, *arguments: str) -> None:
        """Start `pbdag ARGUMENTS` with the service's settings (stopped with it)."""
        with self.log.open("ab") as log:
            self.processes.append(
                subprocess.Popen(
                    [sys.executable, "-m", "service.cli", *arguments],
                    env=self.env,
                    cwd=REPO,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )


@contextlib.contextmanager
def running_service(data: Path, *serve_options: str, **settings: str) -> Iterator[Service]:
    """`pbdag serve` (with its worker unless `--no-worker`) on a free loopback port, SQLite and
    blobs under `data`, `settings` as PBDAG_* variables."""
    port = free_port()
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(data),
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",  # the ingest runs on 127.0.0.1
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",  # --wait polls batch statuses
        **{f"PBDAG_{name.upper()}": value for name, value in settings.items()},
    }
    env.pop("PBDAG_DATABASE_URL", None)  # SQLite in the data directory
    service = Service(f"http://127.0.0.1:{port}", env, data / "service.log", [])
    service.start("serve", "--port", str(port), *serve_options)
    try:
        wait_healthy(service.url)
        yield service
    finally:
        for process in service.processes:
            process.terminate()
        for process in service.processes:
            process.wait(timeout=30)


@pytest.fixture(scope="session")
def service_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The URL of the service the ingest tests share."""
    with running_service(tmp_path_factory.mktemp("service")) as service:
        yield service.url


@dataclass(frozen=True)
class Recordings:
    """What the tests ingest: the folder (with `masks/`), the bags and the label map."""

    folder: Path
    bag: Path
    gappy_bag: Path  # frame 7 has no /tf nor /odom, frame 12 no label image
    float_bag: Path  # 32FC1 depth in metres (NaN: no measurement), one latched camera info
    mcap_bag: Path  # the first 5 frames in MCAP storage
    labels: Path


@pytest.fixture(scope="session")
def recordings(real_kitchen: Path, tmp_path_factory: pytest.TempPathFactory) -> Recordings:
    """The recordings, written once from the first 20 real frames."""
    from tests.ingest.recordings import write_bag, write_folder, write_label_map  # rosbags

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
        float_bag=write_bag(
            real_kitchen, root / "float_bag", 5, float_depth=True, camera_info_once=True
        ),
        mcap_bag=write_bag(real_kitchen, root / "mcap_bag", 5, mcap=True),
        labels=write_label_map(root / "labels.json"),
    )


@pytest.fixture(autouse=True)
def _logging_as_a_new_process() -> Iterator[None]:
    """`pbdag ingest` runs in this process: the root logger as a fresh process has it (no
    handler an earlier test's `configure_logging` left behind, whose INFO lines would join the
    one line of stderr an error prints)."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    root.handlers.clear()
    root.setLevel(logging.WARNING)
    try:
        yield
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)
