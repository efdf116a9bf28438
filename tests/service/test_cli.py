"""`pbdag rebuild` and `pbdag worker --drain` as a user runs them."""

from __future__ import annotations

from pathlib import Path

import pytest
import sqlalchemy as sa

from service.app import create_app
from service.bootstrap import build_container
from service.cli import main
from service.settings import Settings
from service.store.tables import tracks
from tests.clients import local_client
from tests.wire_scenes import batch


def test_worker_drain_then_rebuild_reports_no_difference_then_a_tampered_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    container = build_container(Settings(snapshot_interval=5, allow_anonymous_local=True))
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "cli"}).json()["id"]
        for i in range(6):
            assert (
                client.post(
                    f"/v1/scenes/{scene_id}/batches", json=batch(f"b{i}", i, mug=i < 3)
                ).status_code
                == 202
            )
    assert main(["worker", "--drain"]) == 0
    assert "processed 6 batches" in capsys.readouterr().out
    assert main(["rebuild"]) == 0
    assert "rebuild: no difference" in capsys.readouterr().out
    with container.engine.begin() as connection:
        connection.execute(sa.update(tracks).values(p_exist=0.5))
    assert main(["rebuild"]) == 1
    out = capsys.readouterr().out
    assert "DIFFERED" in out and "trk-000001" in out
    assert main(["rebuild", "--scene", scene_id]) == 0
