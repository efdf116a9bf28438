"""The short fault run of CI (`make soak` runs the long one): kills, a poison batch, and the
log must stay gapless, exactly-once and rebuildable."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import store_backends
from tests.e2e.fault_run import run_fault_run


def runs() -> list[tuple[str, str]]:
    """(database, blobs): SQLite with its folder; PostgreSQL with the blobs in it, each process
    with its own data directory (the default there). PostgreSQL with a shared folder is in
    `make soak` (45 s more here)."""
    postgres = [("postgres", "postgres")] if "postgres" in store_backends() else []
    return [("sqlite", "folder"), *postgres]


@pytest.mark.slow
@pytest.mark.parametrize(("backend", "blobs"), runs())
def test_random_sigkills_lose_nothing_and_duplicate_nothing(
    tmp_path: Path, backend: str, blobs: str, request: pytest.FixtureRequest
) -> None:
    database_url = None
    if backend == "postgres":
        url, schema = request.getfixturevalue("postgres_schema_url")
        database_url = f"{url}?options=-csearch_path%3D{schema}"
    report = run_fault_run(
        kills=6,
        data_dir=tmp_path / "data",
        database_url=database_url,
        poison=backend == "postgres",
        progress=False,
        blob_backend=blobs,
    )
    assert report.blobs == blobs
    assert report.kills == 6 and report.batches_accepted > 6, report
    assert (report.gaps, report.duplicates, report.lost) == (0, 0, []), report
    assert report.rebuild_exit_code == 0, report
    if backend == "postgres":
        assert report.poison == "dead"
