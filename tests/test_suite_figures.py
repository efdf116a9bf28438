"""The suite's figures in docs/install.md come from a run's JUnit report, between markers."""

from __future__ import annotations

import datetime

import pytest

from tests.suite_figures import END, INSTALL_DOC, START, counted, rewritten, sentence

REPORT = """<?xml version="1.0" encoding="utf-8"?><testsuites name="pytest tests">
<testsuite name="pytest" errors="1" failures="2" skipped="39" tests="1321" time="518.1"/>
</testsuites>"""


def test_the_counts_come_from_the_junit_report() -> None:
    run = counted(REPORT, 518.4)
    assert (run.tests, run.failures, run.errors, run.skipped, run.passed) == (1321, 2, 1, 39, 1279)
    with pytest.raises(ValueError, match="no <testsuite>"):
        counted("<testsuites/>", 1.0)


def test_the_sentence_states_counts_time_and_where_they_were_measured() -> None:
    text = sentence(counted(REPORT, 518.4), "bf5c9bc", datetime.date(2026, 12, 3))
    assert "1,321 tests, 1,279 passed, 39 skipped" in text
    assert "in 8 min 38 s" in text and "2026-12-03 at commit bf5c9bc" in text


def test_rewriting_replaces_only_the_marked_text_and_twice_is_once() -> None:
    document = f"before\n{START}\nold figures\n{END}\nafter\n"
    once = rewritten(document, "new figures")
    assert once == f"before\n{START}\nnew figures\n{END}\nafter\n"
    assert rewritten(once, "new figures") == once
    with pytest.raises(ValueError, match="markers"):
        rewritten("no markers here", "new figures")


def test_the_install_page_carries_the_markers() -> None:
    document = INSTALL_DOC.read_text()
    assert document.count(START) == 1 and document.count(END) == 1
    assert document.index(START) < document.index(END)
