"""The client examples (docs/client.md, and the README's) run as written against a real service."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

from api_schema import BatchIn
from pbdag_client import Client
from service.auth import create_token
from tests.client.conftest import Service
from tests.wire_scenes import batch

ROOT = Path(__file__).resolve().parents[2]
CLIENT_GUIDE = ROOT / "docs" / "client.md"
README = ROOT / "README.md"


def python_blocks(page: Path) -> list[str]:
    """The Python blocks of a page, in order."""
    found = re.findall(r"```python\n(.*?)```", page.read_text(), re.DOTALL)
    assert found, f"{page.name} has no Python example"
    return found


def first_python_block(page: Path) -> str:
    """The first Python block of a page."""
    return python_blocks(page)[0]


def run_example(
    code: str, url: str, name: str, namespace: dict[str, object] | None = None
) -> list[str]:
    """The lines an example prints, run against the service at `url` (in `namespace`, for an
    example that continues another)."""
    assert "http://127.0.0.1:8000" in code and len(code.splitlines()) <= 16
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(
            compile(code.replace("http://127.0.0.1:8000", url), name, "exec"),
            {} if namespace is None else namespace,
        )
    return printed.getvalue().splitlines()


def test_the_guide_example_posts_a_frame_and_explains_the_track(service: Service) -> None:
    lines = run_example(first_python_block(CLIENT_GUIDE), service.url, "docs/client.md")
    assert len(lines) == 1 and lines[0].startswith("trk-") and " mug " in lines[0]
    assert "mug) is tentative" in lines[0] and "frame f000001" in lines[0]
    # The README's example then lists that scene's nodes, the hypothesis included.
    listed = run_example(first_python_block(README), service.url, "README.md")
    track_id = lines[0].split()[0]
    assert listed == [f"{track_id} mug tentative None"]


def test_the_guide_follows_the_log_with_the_feed(service: Service) -> None:
    run_example(first_python_block(CLIENT_GUIDE), service.url, "docs/client.md")
    with Client(service.url) as client:  # the scene the example made, and its first add
        first = next(client.events(client.scenes()[-1].id, type="add"))
    feed = python_blocks(CLIENT_GUIDE)[2]
    assert "stream_events" in feed
    printed = run_example(feed, service.url, "docs/client.md (feed)")
    assert printed == [f"{first.seq} add {first.track_id}"]


def test_the_guide_example_deletes_a_half_made_scene_and_renames_the_others(
    service: Service,
) -> None:
    token = create_token(service.container.engine, "guide", ["admin"]).token
    with Client(service.url) as client:
        empty = client.create_scene("sim-demo")
        used = client.create_scene("sim-demo")
        client.rename_scene(used.id, "sim-demo")  # the same name: nothing appended
        client.post_batch(used.id, BatchIn.model_validate(batch("b0", 0)))
        client.wait_for_batch(used.id, "b0")
    code = python_blocks(CLIENT_GUIDE)[3].replace("ADMIN_TOKEN = None", f"ADMIN_TOKEN = {token!r}")
    lines = run_example(code, service.url, "docs/client.md")
    assert f"deleted {empty.id} 1 events 0 batches" in lines
    assert f"kept sim-demo {used.id}" in lines
    with Client(service.url) as client:
        assert empty.id not in [scene.id for scene in client.scenes()]


def test_the_guide_questions_continue_the_first_example(service: Service) -> None:
    first, questions = python_blocks(CLIENT_GUIDE)[:2]
    namespace: dict[str, object] = {}
    [posted] = run_example(first, service.url, "docs/client.md", namespace)
    track_id = posted.split()[0]
    lines = run_example(questions, service.url, "docs/client.md", namespace)
    # The one mug, 1.5 m in front of the camera at the origin, on no fixture, with no
    # appearance; its batch appended the occupancy evidence (seq 1), then its `add` (seq 2).
    assert lines == [f"{track_id} None ['mug'] 0", "tentative 2 True"]
