"""The README's client example runs as written against a real service."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

from tests.client.conftest import Service

README = Path(__file__).resolve().parents[2] / "README.md"


def readme_example() -> str:
    """The first Python block of the README's "Python client" section."""
    section = README.read_text().split("## Python client", 1)[1]
    found = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    assert found is not None, "the README's Python client section has no example"
    return found.group(1)


def test_the_readme_example_posts_a_frame_and_explains_the_track(service: Service) -> None:
    code = readme_example()
    assert "http://127.0.0.1:8000" in code and len(code.splitlines()) <= 16
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(code.replace("http://127.0.0.1:8000", service.url), "README.md", "exec"), {})
    lines = printed.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("trk-") and " mug " in lines[0]
    assert "mug) is tentative" in lines[0] and "frame f000001" in lines[0]
