"""The end-to-end benchmark's quick mode on SQLite: real processes, every batch done, figures
written."""

from __future__ import annotations

import json
import uuid

import pytest

from tests.eval_extra import require_eval_extra

require_eval_extra()  # the benchmark's batches are rendered by the simulator

from bench.bench_service import main  # noqa: E402
from bench.perf_common import RESULTS_DIR  # noqa: E402


@pytest.mark.slow
def test_quick_run_on_sqlite_finishes_every_batch_and_writes_the_figures() -> None:
    name = f"service-test-{uuid.uuid4().hex[:8]}"
    path = RESULTS_DIR / f"{name}.json"
    try:
        main(["--quick", "--configs", "a", "--rate", "10", "--name", name])
        results = json.loads(path.read_text())
    finally:
        path.unlink(missing_ok=True)
    assert list(results["configs"]) == ["a"]
    figures = results["configs"]["a"]
    assert figures["batches"] == 30  # 3 s at 10 per second
    assert figures["accepted"] == figures["done"] == figures["batches"], figures["errors"]
    assert figures["errors"] == []
    assert 0 < figures["throughput"] <= 10.5
    assert 0 < figures["post_p50_ms"] <= figures["post_p99_ms"]
    assert 0 < figures["done_p50_ms"] <= figures["done_p99_ms"] <= figures["done_max_ms"]
    assert figures["decide_mean_ms"] > 0 and figures["append_mean_ms"] > 0
    assert figures["cpu_seconds"]["api"] > 0
    assert results["object_masks"] == 20 and min(results["fixture_masks"]) >= 1
    assert set(results["stage_breakdown_ms"]) >= {"decode", "decide", "fold"}
    assert "one_worker_at_rate" in results["goals"]
