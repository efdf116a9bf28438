"""What the viewer's browser tests share: the demo scene served by `pbdag serve` and built over
HTTP, where Chromium lives, and the page helpers. Imported by tests/viewer/test_viewer_browser.py
once it has checked that the eval extra (the simulator's detector) is installed."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Locator, Page

from tests.core.rendered import TABLE_VIEWS
from tests.e2e.fixture_world import DISCOVERY, ROOM, wire_batches

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "test-artifacts" / "viewer"
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
AMBIGUOUS_TABLE = {"table": {"table": 0.50, "desk": 0.48}}
LOOPBACK = frozenset({"127.0.0.1", "localhost", "::1"})
TIMEOUT_MS = 20_000


@dataclass(frozen=True)
class DemoScene:
    url: str
    scene_id: str
    head: int
    mug_id: str
    removed_at: int
    last_published: int  # the mug's last seq in the published graph, before misses demoted it
    table_id: str


def chromium_or_skip() -> None:
    """Skip without Debian's Chromium, except on CI, where make test installs it."""
    if CHROMIUM.exists():
        return
    reason = f"Debian's chromium is not installed at {CHROMIUM} (scripts/system-deps.sh does it)"
    if os.environ.get("CI"):
        pytest.fail(reason)
    pytest.skip(reason)


def build_scene(client: httpx.Client) -> DemoScene:
    """Post the discovery and the removal as batches and wait until every one is done."""
    scene_id: str = client.post("/v1/scenes", json={"name": "viewer demo"}).json()["id"]
    bodies = wire_batches(ROOM, DISCOVERY, "d", ambiguity=AMBIGUOUS_TABLE)
    bodies += wire_batches(ROOM.without("mug"), TABLE_VIEWS * 4, "r", ambiguity=AMBIGUOUS_TABLE)
    for body in bodies:
        response = client.post(f"/v1/scenes/{scene_id}/batches", json=body)
        assert response.status_code == 202, response.text
    deadline = time.monotonic() + 120
    last = bodies[-1]["batch_id"]
    while client.get(f"/v1/scenes/{scene_id}/batches/{last}").json()["status"] != "done":
        assert time.monotonic() < deadline, "the batches were not processed in time"
        time.sleep(0.2)
    graph = client.get(f"/v1/scenes/{scene_id}/graph", params={"include": "all"}).json()
    by_label = {node["label"]: node for node in graph["nodes"]}
    assert by_label["mug"]["state"] == "removed"
    assert graph["pending_verifications"] == [by_label["table"]["id"]]
    removals = client.get(
        f"/v1/scenes/{scene_id}/events",
        params={"type": "remove", "track_id": by_label["mug"]["id"]},
    ).json()["events"]
    assert len(removals) == 1
    doubted = client.get(
        f"/v1/scenes/{scene_id}/events",
        params={"type": "demote", "track_id": by_label["mug"]["id"]},
    ).json()["events"]
    last_published = (doubted[0]["seq"] if doubted else removals[0]["seq"]) - 1
    published = client.get(f"/v1/scenes/{scene_id}/graph", params={"as_of": last_published}).json()
    assert by_label["mug"]["id"] in {node["id"] for node in published["nodes"]}
    return DemoScene(
        url=str(client.base_url).rstrip("/"),
        scene_id=scene_id,
        head=graph["seq"],
        mug_id=by_label["mug"]["id"],
        removed_at=removals[0]["seq"],
        last_published=last_published,
        table_id=by_label["table"]["id"],
    )


def shot(page: Page, name: str) -> None:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / f"{name}.png"), full_page=True)


def shown_at(page: Page, seq: int) -> None:
    """Wait until the page has drawn the graph, events and selection of `seq`."""
    page.wait_for_selector(f'body[data-seq="{seq}"]', state="attached")


def head_now(demo: DemoScene) -> int:
    """The scene's head as the API reports it (a verdict in another test moves it on)."""
    head: int = httpx.get(f"{demo.url}/v1/scenes/{demo.scene_id}").json()["head_seq"]
    return head


def post_more(demo: DemoScene, prefix: str) -> None:
    """More views of the room as batches, processed: the head moves on."""
    before = head_now(demo)
    with httpx.Client(base_url=demo.url, timeout=30.0) as client:
        bodies = wire_batches(ROOM.without("mug"), TABLE_VIEWS, prefix, ambiguity=AMBIGUOUS_TABLE)
        for body in bodies:
            response = client.post(f"/v1/scenes/{demo.scene_id}/batches", json=body)
            assert response.status_code == 202, response.text
        deadline = time.monotonic() + 60
        while head_now(demo) == before:
            assert time.monotonic() < deadline, "the batches appended nothing in time"
            time.sleep(0.2)


def track_item(page: Page, label: str) -> Locator:
    return page.locator(f'#tracks li[data-label="{label}"]')


def overlapping(boxes: list[list[float]]) -> list[tuple[int, int]]:
    """Pairs of label boxes (x, y, w, h) that cover one another."""
    return [
        (i, j)
        for i, (ax, ay, aw, ah) in enumerate(boxes)
        for j, (bx, by, bw, bh) in enumerate(boxes)
        if i < j and ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah
    ]


def post_and_wait(demo: DemoScene, prefix: str) -> int:
    """More views of the room as batches, every one processed; the new head."""
    with httpx.Client(base_url=demo.url, timeout=30.0) as client:
        bodies = wire_batches(ROOM.without("mug"), TABLE_VIEWS, prefix, ambiguity=AMBIGUOUS_TABLE)
        for body in bodies:
            response = client.post(f"/v1/scenes/{demo.scene_id}/batches", json=body)
            assert response.status_code == 202, response.text
        last = f"/v1/scenes/{demo.scene_id}/batches/{bodies[-1]['batch_id']}"
        deadline = time.monotonic() + 60
        while client.get(last).json()["status"] != "done":
            assert time.monotonic() < deadline, "the batches were not processed in time"
            time.sleep(0.2)
    return head_now(demo)


def counter(page: Page, name: str) -> int:
    return int(page.locator("body").get_attribute(f"data-{name}") or 0)


@dataclass(frozen=True)
class Browsed:
    page: Page
    errors: list[str]  # script errors and console errors (CSP violations among them)
