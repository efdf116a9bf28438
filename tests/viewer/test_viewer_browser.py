"""The viewer and /docs in Debian's headless Chromium, against a real `pbdag serve`.

A table (ambiguous: table or desk, so it waits for a verdict), a counter and a mug on the table;
then the mug is taken away and seen missing until it is removed. Screenshots go to
test-artifacts/viewer/; the assertions are on the DOM.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.sync_api import (
    Browser,
    ConsoleMessage,
    Route,
    expect,
    sync_playwright,
)

from tests.e2e.fault_run import free_port, wait_healthy
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the scene is rendered by the simulator's detector

from tests.viewer.browsing import (  # noqa: E402
    CHROMIUM,
    CHROMIUM_ARGS,
    LOOPBACK,
    REPO,
    TIMEOUT_MS,
    Browsed,
    DemoScene,
    build_scene,
    chromium_or_skip,
    counter,
    head_now,
    overlapping,
    post_and_wait,
    post_more,
    shot,
    shown_at,
    track_item,
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DemoScene]:
    """`pbdag serve` on a free loopback port (SQLite in a temporary data dir) with the scene."""
    chromium_or_skip()
    data = tmp_path_factory.mktemp("viewer")
    port = free_port()
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(data / "data"),
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",  # the browser is on 127.0.0.1, as a local user
    }
    env.pop("PBDAG_DATABASE_URL", None)
    log = data / "service.log"
    with log.open("ab") as handle:
        process = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve", "--port", str(port)],
            env=env,
            cwd=REPO,
            stdout=handle,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url)
        with httpx.Client(base_url=url, timeout=30.0) as client:
            yield build_scene(client)
    finally:
        process.terminate()
        process.wait(timeout=30)


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """Debian's Chromium driven by Playwright (which never downloads a browser here)."""
    chromium_or_skip()
    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
        )
        try:
            yield launched
        finally:
            launched.close()


@pytest.fixture
def browsed(browser: Browser) -> Iterator[Browsed]:
    """A fresh page in its own context, recording errors."""
    context = browser.new_context(viewport={"width": 1400, "height": 900})
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors: list[str] = []

    def console(message: ConsoleMessage) -> None:
        if message.type == "error":
            errors.append(f"{message.text} ({message.location.get('url')})")

    page.on("pageerror", lambda error: errors.append(str(error)))
    page.on("console", console)
    try:
        yield Browsed(page, errors)
    finally:
        context.close()


def test_slider_explanation_and_verdict_in_the_browser(demo: DemoScene, browsed: Browsed) -> None:
    page = browsed.page
    page.goto(f"{demo.url}/viewer?scene={demo.scene_id}")
    shown_at(page, demo.head)
    assert page.locator("#seq").get_attribute("max") == str(demo.head)
    assert track_item(page, "counter").get_attribute("data-state") == "confirmed"
    counter = track_item(page, "counter")  # its id beside its label: two desks are told apart
    assert counter.locator(".track-id").text_content() == f"{counter.get_attribute('data-track')} "
    assert track_item(page, "mug").count() == 0  # removed: not in the published graph
    assert track_item(page, "table").count() == 0  # waits for a verdict
    assert page.locator("#map").get_attribute("data-nodes") == "1"
    assert page.locator("#events li").count() > 0
    assert page.locator(f'#events li[data-seq="{demo.head}"]').count() == 1
    shot(page, "1-head")
    page.fill("#search", "sofa")  # a question: none at this seq
    page.click("#search-form button")
    expect(page.locator("#search-results")).to_contain_text(f"No sofa at seq {demo.head}")
    page.fill("#search", "mug")  # the removed mug is still an answer, with its parent
    page.click("#search-form button")
    found = page.locator(f'#search-results li[data-track="{demo.mug_id}"]')
    expect(found).to_contain_text("removed p=")
    assert demo.table_id in (found.text_content() or "")

    # Before the removal the mug is back, confirmed on the table.
    before = demo.last_published
    page.locator("#seq").fill(str(before))
    shown_at(page, before)
    assert page.locator("#seq-label").text_content() == str(before)
    mug = track_item(page, "mug")
    assert mug.get_attribute("data-state") == "confirmed"
    assert mug.get_attribute("data-track") == demo.mug_id
    assert demo.table_id in (mug.text_content() or "")  # "on table (trk-...)"
    assert page.locator(f'#events li[data-seq="{before}"]').count() == 1
    shot(page, "2-before-removal")

    # Its belief then, and the explanation of its removal from the log.
    mug.click()
    explanation = page.locator("#explanation")
    explanation.wait_for()
    summary = explanation.text_content() or ""
    assert f"was removed at seq {demo.removed_at}" in summary, summary
    assert "visibility-admissible misses" in summary
    assert page.locator("#track-detail li").count() >= 1  # the visible misses behind it
    detail = page.locator("#track-detail dl").text_content() or ""
    assert "confirmed" in detail and "mug" in detail
    assert page.locator("#tracks li.selected").get_attribute("data-track") == demo.mug_id
    shot(page, "3-explanation")

    # Confirm the pending table: the head moves on and the table is published.
    pending = page.locator(f'#verifications li[data-track="{demo.table_id}"]')
    assert pending.get_attribute("data-label") == "table"
    pending.locator("button.confirm").click()
    track_item(page, "table").wait_for()
    head = head_now(demo)
    assert head > demo.head
    shown_at(page, head)
    table = track_item(page, "table")
    assert table.get_attribute("data-state") == "confirmed"
    assert table.get_attribute("data-track") == demo.table_id
    assert page.locator("#verifications li[data-track]").count() == 0
    assert page.locator("#seq").get_attribute("max") == str(head)
    assert page.locator('#events li[data-type="verify"]').count() == 1
    shot(page, "4-table-confirmed")
    graph = httpx.get(f"{demo.url}/v1/scenes/{demo.scene_id}/graph").json()
    assert demo.table_id in {node["id"] for node in graph["nodes"]}
    assert browsed.errors == []


def test_a_typed_token_is_sent_as_a_bearer_header(demo: DemoScene, browsed: Browsed) -> None:
    page = browsed.page
    page.goto(f"{demo.url}/viewer?scene={demo.scene_id}")
    shown_at(page, head_now(demo))
    requests: list[str | None] = []
    page.on("request", lambda request: requests.append(request.headers.get("authorization")))
    page.fill("#token", "pbdag_nosuch_token")
    page.click("#token-form button")
    # The page forbids eval (CSP), so wait on selectors rather than on evaluated functions.
    expect(page.locator("#status")).to_contain_text("needs a token", timeout=TIMEOUT_MS)
    expect(page.locator("#token")).to_have_class("needed")  # the field to fill, outlined
    expect(page.locator("#token")).to_be_focused()
    assert "Bearer pbdag_nosuch_token" in requests
    shot(page, "5-bad-token")
    page.fill("#token", "")
    page.click("#token-form button")
    expect(page.locator("#status")).to_have_class("ok", timeout=TIMEOUT_MS)
    assert requests[-1] is None


def test_docs_render_with_every_other_host_blocked(demo: DemoScene, browsed: Browsed) -> None:
    page = browsed.page
    blocked: list[str] = []

    def only_loopback(route: Route) -> None:
        if urlsplit(route.request.url).hostname in LOOPBACK:
            route.continue_()
        else:
            blocked.append(route.request.url)
            route.abort()

    page.context.route("**/*", only_loopback)
    page.goto(f"{demo.url}/docs")
    page.wait_for_selector(".opblock", state="visible")
    document = httpx.get(f"{demo.url}/openapi.json").json()
    operations = sum(len(methods) for methods in document["paths"].values())
    assert page.locator(".opblock").count() == operations
    assert "PBD-AG" in (page.locator(".information-container .title").text_content() or "")
    shot(page, "6-docs-offline")
    assert blocked == []  # nothing even tried to leave the machine
    assert browsed.errors == []


def test_follow_the_head_comes_back_after_scrubbing(demo: DemoScene, browsed: Browsed) -> None:
    page = browsed.page
    page.goto(f"{demo.url}/viewer?scene={demo.scene_id}")
    head = head_now(demo)
    shown_at(page, head)
    follow = page.locator("#follow")
    assert follow.is_checked()
    page.locator("#seq").fill(str(demo.last_published))  # scrub back: no longer following
    shown_at(page, demo.last_published)
    assert not follow.is_checked()
    # New events while scrubbed back: the view stays where the user put it.
    post_more(demo, "f1")
    newer = head_now(demo)
    deadline = time.monotonic() + 20  # the page polls the head
    while page.locator("#seq").get_attribute("max") != str(newer):
        assert time.monotonic() < deadline, "the page did not see the new head"
        page.wait_for_timeout(100)
    assert page.locator("body").get_attribute("data-seq") == str(demo.last_published)
    follow.check()  # back to the head at once
    shown_at(page, newer)
    assert page.locator("#seq").input_value() == str(newer)
    post_more(demo, "f2")  # and on to the next head by itself
    shown_at(page, head_now(demo))
    assert follow.is_checked()
    assert browsed.errors == []


@pytest.mark.parametrize("viewport", [(1400, 900), (520, 420)])
def test_labels_never_cover_each_other_and_a_scale_bar_fits(
    demo: DemoScene, browser: Browser, viewport: tuple[int, int]
) -> None:
    context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
    try:
        page = context.new_page()
        page.set_default_timeout(TIMEOUT_MS)
        page.goto(f"{demo.url}/viewer?scene={demo.scene_id}")
        shown_at(page, head_now(demo))
        page.locator("#show-all").check()  # every track, the removed mug among them
        canvas = page.locator("#map")
        expect(canvas).not_to_have_attribute("data-nodes", "1")
        # One render's attributes, read at once: the view may draw again between two reads.
        drawn = canvas.evaluate("el => ({...el.dataset})")
        nodes = int(drawn.get("nodes") or 0)
        boxes = json.loads(drawn.get("labelBoxes") or "[]")
        assert 1 <= len(boxes) <= nodes
        assert overlapping(boxes) == []
        metres_text = drawn.get("scaleBar") or ""
        match = re.fullmatch(r"(\d+) (m|cm)", metres_text)
        assert match, metres_text
        metres = int(match.group(1)) / (100 if match.group(2) == "cm" else 1)
        bar_px = float(drawn.get("scaleBarPx") or 0)
        px_per_m = float(drawn.get("pxPerM") or 0)
        assert bar_px == pytest.approx(metres * px_per_m, abs=0.1)
        assert 48 <= bar_px <= 120  # a 1, 2 or 5 step that fits in 120 pixels
        shot(page, f"7-labels-{viewport[0]}")
    finally:
        context.close()


def test_following_the_head_reads_the_feed_rather_than_polling(
    demo: DemoScene, browsed: Browsed
) -> None:
    page = browsed.page
    requested: list[tuple[str, str | None]] = []  # (path, Last-Event-ID)
    page.on(
        "request",
        lambda r: requested.append((urlsplit(r.url).path, r.headers.get("last-event-id"))),
    )
    scene_path = f"/v1/scenes/{demo.scene_id}"
    page.goto(f"{demo.url}/viewer?scene={demo.scene_id}")
    shown_at(page, head_now(demo))
    follow = page.locator("#follow")
    # Batches arrive while the page is open: the feed brings each new head.
    shown_at(page, post_and_wait(demo, "g1"))
    assert counter(page, "feed-events") >= 1
    # Scrub back and forth: no longer following; new events leave the view where it is.
    page.locator("#seq").fill(str(demo.last_published))
    shown_at(page, demo.last_published)
    page.locator("#seq").fill(str(demo.last_published + 1))
    shown_at(page, demo.last_published + 1)
    assert not follow.is_checked()
    newer = post_and_wait(demo, "g2")
    deadline = time.monotonic() + 20  # unchecked, the page polls the head for the slider
    while page.locator("#seq").get_attribute("max") != str(newer):
        assert time.monotonic() < deadline, "the page did not see the new head"
        page.wait_for_timeout(100)
    assert page.locator("body").get_attribute("data-seq") == str(demo.last_published + 1)
    # Checked again: the newest seq at once, then every new one through the feed.
    mark, refreshed = len(requested), counter(page, "feed-refreshes")
    follow.check()
    shown_at(page, newer)
    newest = post_and_wait(demo, "g3")
    shown_at(page, newest)
    page.wait_for_timeout(1000)  # nothing more should come
    since = [path for path, _ in requested[mark:]]
    refreshes = counter(page, "feed-refreshes") - refreshed
    assert refreshes >= 1
    assert scene_path not in since  # no poll of the head while following
    assert since.count(f"{scene_path}/graph") == 1 + refreshes  # the jump, then the feed's
    streams = [last for path, last in requested[mark:] if path == f"{scene_path}/events/stream"]
    assert streams and streams[0] == str(newer)  # resumed from the head it jumped to
    assert page.locator("#seq").input_value() == str(newest)
    assert follow.is_checked()
    assert browsed.errors == []
