"""`pbdag scenes list|rename|delete` as an operator runs them: what they print first, their exit
codes, the confirmation a deletion asks for."""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.app import create_app
from service.bootstrap import Container, build_container
from service.cli import main
from service.settings import Settings
from service.store import scene_deletion
from service.store.blobs import ORPHAN_GRACE_SECONDS
from tests.clients import local_client
from tests.service.scene_rows import rows_of
from tests.wire_scenes import batch


@pytest.fixture
def database(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Container]:
    """The default SQLite database under PBDAG_DATA_DIR, as `pbdag` finds it."""
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    container = build_container(Settings(allow_anonymous_local=True))
    try:
        yield container
    finally:
        container.engine.dispose()


def two_scenes(container: Container) -> tuple[str, str]:
    """`kitchen` with one batch done and one queued, and an empty `sim-demo`."""
    with local_client(create_app(container)) as client:
        kitchen = client.post("/v1/scenes", json={"name": "kitchen"}).json()["id"]
        demo = client.post("/v1/scenes", json={"name": "sim-demo"}).json()["id"]
        client.post(f"/v1/scenes/{kitchen}/batches", json=batch("b0", 0))
        assert main(["worker", "--drain"]) == 0
        client.post(f"/v1/scenes/{kitchen}/batches", json=batch("b1", 1))
    return str(kitchen), str(demo)


def test_list_prints_each_scene_with_its_head_and_queued_batches(
    database: Container, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scenes", "list"]) == 0
    assert capsys.readouterr().out == "no scenes\n"
    kitchen, demo = two_scenes(database)
    capsys.readouterr()
    assert main(["scenes", "list"]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("pbdag: database sqlite:///")
    header, *lines = captured.out.splitlines()
    assert header.split() == ["id", "name", "head", "created", "(UTC)", "quarantined", "queued"]
    head = database.log.scene(kitchen).head_seq
    assert len(lines) == 2 and head > 0
    assert lines[0].split()[:3] == [kitchen, "kitchen", str(head)]
    assert lines[0].split()[-2:] == ["no", "1"]
    assert lines[1].split()[:3] == [demo, "sim-demo", "0"] and lines[1].split()[-2:] == ["no", "0"]


def test_rename_appends_the_name_and_refuses_unknown_scenes_and_bad_names(
    database: Container, capsys: pytest.CaptureFixture[str]
) -> None:
    kitchen, _demo = two_scenes(database)
    capsys.readouterr()
    assert main(["scenes", "rename", kitchen, "kitchen (old)"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{kitchen}: renamed 'kitchen' -> 'kitchen (old)' (seq ")
    assert database.log.scene(kitchen).name == "kitchen (old)"
    assert database.log.replay(kitchen).name == "kitchen (old)"
    assert main(["scenes", "rename", kitchen, "kitchen (old)"]) == 0
    assert "nothing appended" in capsys.readouterr().out

    assert main(["scenes", "rename", "scn-000000000000", "x"]) == 1
    unknown = capsys.readouterr().err.splitlines()
    assert unknown[-1] == "pbdag scenes rename: scene 'scn-000000000000' does not exist"
    assert main(["scenes", "rename", kitchen, "bad\tname"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pbdag scenes rename: NAME: ") and err.count("\n") == 1
    assert database.log.scene(kitchen).name == "kitchen (old)"


def test_delete_asks_for_the_id_and_deletes_only_when_it_is_typed(
    database: Container, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    kitchen, demo = two_scenes(database)
    before = rows_of(database.engine, kitchen)
    capsys.readouterr()
    for typed in ("", "yes\n", f"{demo}\n"):
        monkeypatch.setattr("sys.stdin", io.StringIO(typed))
        assert main(["scenes", "delete", kitchen]) == 1
        err = capsys.readouterr().err
        assert f"delete scene {kitchen} (kitchen) and everything it holds?" in err
        assert err.splitlines()[-1].endswith("pbdag scenes delete: not confirmed; nothing deleted")
        assert rows_of(database.engine, kitchen) == before

    # Judged as `pbdag gc` would an hour on: a younger blob file is left to its sweep.
    later = time.time() + ORPHAN_GRACE_SECONDS + 60
    monkeypatch.setattr(scene_deletion, "clock", lambda: later)
    monkeypatch.setattr("sys.stdin", io.StringIO(f"{kitchen}\n"))
    assert main(["scenes", "delete", kitchen]) == 0
    out = capsys.readouterr().out
    assert out.startswith(
        f"{kitchen}: deleted {before['events']} events, 2 batches, 2 raw batch blobs ("
    )
    assert set(rows_of(database.engine, kitchen).values()) == {0}
    assert [scene.id for scene in database.log.scenes()] == [demo]

    assert main(["scenes", "delete", "--yes", demo]) == 0
    assert capsys.readouterr().out.startswith(f"{demo}: deleted 1 events, 0 batches, 0 raw")
    assert main(["scenes", "delete", "--yes", demo]) == 1
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"pbdag scenes delete: scene '{demo}' does not exist"
    )


def test_the_scene_commands_refuse_a_database_that_does_not_exist(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path / "nowhere"))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    for command in (["list"], ["rename", "scn-1", "x"], ["delete", "--yes", "scn-1"]):
        assert main(["scenes", *command]) == 2
        err = capsys.readouterr().err
        assert err.startswith("pbdag: no database file ") and err.count("\n") == 1
    assert not (tmp_path / "nowhere").exists()
