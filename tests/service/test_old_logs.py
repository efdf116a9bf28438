"""A database written by the code before event topics, on every store backend: today's code
replays it to the same states, serves its rows, and `pbdag rebuild` finds no difference."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import orjson
import pytest
import sqlalchemy as sa

from core.upcasters import LEGACY_NAMES
from service.app import create_app
from service.bootstrap import Container
from service.cli import main
from service.store.projection import rebuild_scene
from service.store.tables import events
from service.worker import Worker
from tests.clients import local_client
from tests.golden_logs import BEFORE_EVENT_TOPICS, laid_out_as
from tests.wire_scenes import batch


def test_the_old_database_replays_and_loads_to_the_states_the_old_code_folded(
    old_database: tuple[str, Container, list[str]],
) -> None:
    _url, container, scene_ids = old_database
    golden = BEFORE_EVENT_TOPICS.states()
    for number, scene_id in enumerate(scene_ids):
        written = golden[str(number)]
        expected = orjson.dumps(written)
        replayed = container.log.replay(scene_id).to_dict()
        assert orjson.dumps(laid_out_as(replayed, written)) == expected
        # Through load_state (the old code's snapshots, of an older format, are replayed
        # instead), and at a seq before the last one.
        loaded = container.log.load_state(scene_id)
        assert orjson.dumps(laid_out_as(loaded.to_dict(), written)) == expected
        head = loaded.head_seq
        assert container.log.load_state(scene_id, head - 1).to_dict() == (
            container.log.replay(scene_id, head - 1).to_dict()
        )


def test_pbdag_rebuild_finds_no_difference_in_the_old_database(
    old_database: tuple[str, Container, list[str]],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
) -> None:
    url, _container, scene_ids = old_database
    monkeypatch.setenv("PBDAG_DATABASE_URL", url)
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path / "data"))
    assert main(["rebuild"]) == 0
    out = capsys.readouterr().out.splitlines()
    events = [len(scene) for _number, scene in sorted(BEFORE_EVENT_TOPICS.scenes().items())]
    # The old code's snapshots are of an older state format (the params have gained the
    # extensions' switches since): rewritten, not a difference.
    older = Counter(row["scene_id"] for row in BEFORE_EVENT_TOPICS.tables()["snapshots"])
    # Its object tracks' beliefs lack when each was first observed (derived from its `add`):
    # rewritten with it, not a difference.
    objects = Counter(
        row["scene_id"] for row in BEFORE_EVENT_TOPICS.tables()["tracks"] if row["kind"] == "object"
    )
    assert out == [
        *(
            f"{scene_id}: {count} events replayed; projections identical"
            + (
                f"; {older[scene_id]} snapshots in an older format rewritten"
                if older[scene_id]
                else ""
            )
            + (
                f"; {objects[scene_id]} tracks rewritten with the fields added since"
                if objects[scene_id]
                else ""
            )
            for scene_id, count in zip(scene_ids, events, strict=True)
        ),
        "rebuild: no difference",
    ]


def test_the_api_serves_old_rows_with_their_audit_type_and_their_topic(
    old_database: tuple[str, Container, list[str]],
) -> None:
    _url, container, scene_ids = old_database
    with local_client(create_app(container)) as client:
        kitchen, session = scene_ids[1], scene_ids[2]
        updates = client.get(
            f"/v1/scenes/{kitchen}/events", params={"type": "update", "limit": 1000}
        ).json()["events"]
        stored = [r for r in BEFORE_EVENT_TOPICS.scenes()[1] if r["type"] == "update"]
        assert [e["seq"] for e in updates] == [r["seq"] for r in stored]
        assert {e["type"] for e in updates} == {"update"}
        assert {e["topic"] for e in updates} == {
            "object_observed",
            "fixture_observed",
            "visible_miss",
        }
        # The payload as stored, byte for byte, whatever its form.
        by_seq = {r["seq"]: r["details"] for r in BEFORE_EVENT_TOPICS.scenes()[2]}
        page = client.get(f"/v1/scenes/{session}/events", params={"limit": 1000}).json()
        for event in page["events"]:
            assert orjson.dumps(event["details"]).decode() == by_seq[event["seq"]]
        loaded = [e for e in page["events"] if e["type"] == "baseline_loaded"]
        assert [e["topic"] for e in loaded] == ["baseline_loaded"]  # its payload's old form
        graph = client.get(f"/v1/scenes/{session}/graph", params={"include": "all"})
        assert graph.status_code == 200 and graph.json()["nodes"]


def test_an_old_scene_takes_new_batches_and_its_mixed_log_rebuilds_the_same(
    old_database: tuple[str, Container, list[str]],
) -> None:
    _url, container, scene_ids = old_database
    mug = scene_ids[3]
    old = len(BEFORE_EVENT_TOPICS.scenes()[3])
    with local_client(create_app(container)) as client:
        for index in (10, 11):
            body = batch(f"new-{index}", index)
            assert client.post(f"/v1/scenes/{mug}/batches", json=body).status_code == 202
        assert Worker(container).drain() == 2
        updates = client.get(
            f"/v1/scenes/{mug}/events", params={"type": "update", "limit": 1000}
        ).json()["events"]
    # New rows are stored under their topics, old ones keep their names; `type=update` finds both.
    with container.engine.connect() as connection:
        names = connection.execute(
            sa.select(events.c.seq, events.c.type).where(events.c.scene_id == mug)
        ).all()
    assert {name for seq, name in names if seq < old} >= {"add", "update"}
    assert {name for seq, name in names if seq >= old}.isdisjoint(LEGACY_NAMES)
    assert min(e["seq"] for e in updates) < old <= max(e["seq"] for e in updates)
    assert {e["type"] for e in updates} == {"update"}
    assert container.log.load_state(mug).to_dict() == container.log.replay(mug).to_dict()
    assert rebuild_scene(container.log, mug).identical
