"""The Quick start demo end to end: service on SQLite, simulated robot, summary and baseline."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_demo_runs_to_its_summary_and_freezes_a_baseline(tmp_path: Path) -> None:
    env = {**os.environ, "PBDAG_DATA_DIR": str(tmp_path / "data")}
    env.pop("PBDAG_DATABASE_URL", None)
    done = subprocess.run(
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
            "0",
        ],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout
    assert "table" in out and "counter" in out and "Where to look:" in out
    assert "baseline v1 frozen" in out
    assert (tmp_path / "data" / "pbdag.db").exists()
