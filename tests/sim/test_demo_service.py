"""The Quick start demo end to end: service on SQLite, simulated robot, summary and baseline."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
from pathlib import Path

from sim.demo_service import listen

REPO = Path(__file__).resolve().parents[2]


def busy_port() -> socket.socket:
    """A loopback socket listening on a free port, as another program's would."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen()
    return sock


def test_a_busy_port_is_reported_and_another_one_taken() -> None:
    with busy_port() as taken:
        port = taken.getsockname()[1]
        sock, note = listen(port)
        with sock:
            assert sock.getsockname()[1] != port
            assert note is not None and f"Port {port} is busy" in note
            assert f"serving on port {sock.getsockname()[1]} instead" in note
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        free = probe.getsockname()[1]
    sock, note = listen(free)
    with sock:
        assert sock.getsockname()[1] == free and note is None


def test_demo_runs_to_its_summary_and_freezes_a_baseline(tmp_path: Path) -> None:
    env = {**os.environ, "PBDAG_DATA_DIR": str(tmp_path / "data")}
    env.pop("PBDAG_DATABASE_URL", None)
    with busy_port() as taken:
        port = taken.getsockname()[1]
        done = run_demo(env, port)
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout
    # The port another program holds is named, and the URL actually served is printed.
    assert f"Port {port} is busy" in out
    served = re.search(r"PBD-AG is serving on http://127\.0\.0\.1:(\d+) ", out)
    assert served is not None and int(served.group(1)) != port
    assert f"http://127.0.0.1:{served.group(1)}/docs" in out
    assert "table" in out and "counter" in out and "Where to look:" in out
    assert "baseline v1 frozen" in out
    assert (tmp_path / "data" / "pbdag.db").exists()


def run_demo(env: dict[str, str], port: int) -> subprocess.CompletedProcess[str]:
    """The demo, shortened, exiting once its run is processed."""
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "sim.demo_service",
            "--frames",
            "60",
            "--pace",
            "0",
            "--exit",
            "--port",
            str(port),
        ],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
