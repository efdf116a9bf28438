"""The test suite's figures in docs/install.md, measured rather than typed.

    python -m tests.suite_figures            # run pytest as `make test` does, print the figures
    python -m tests.suite_figures --write    # and rewrite them in docs/install.md

Runs the whole suite once (about ten minutes on two cores), reads the counts from pytest's JUnit
XML report and the wall time from the clock, and replaces the text between the
`suite-figures` markers of docs/install.md. A failing suite writes nothing and exits non-zero.
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INSTALL_DOC = ROOT / "docs" / "install.md"
START, END = "<!-- suite-figures:start -->", "<!-- suite-figures:end -->"


@dataclass(frozen=True)
class SuiteRun:
    """What one run of the suite counted, and how long it took."""

    tests: int
    failures: int
    errors: int
    skipped: int
    seconds: float

    @property
    def passed(self) -> int:
        return self.tests - self.failures - self.errors - self.skipped


def counted(junit_xml: str, seconds: float) -> SuiteRun:
    """The counts of a JUnit XML report (pytest writes one <testsuite> inside <testsuites>)."""
    root = ET.fromstring(junit_xml)
    suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
    if not suites:
        raise ValueError("the report holds no <testsuite>")
    totals = {
        name: sum(int(suite.get(name, "0")) for suite in suites)
        for name in ("tests", "failures", "errors", "skipped")
    }
    return SuiteRun(seconds=seconds, **totals)


def sentence(run: SuiteRun, commit: str, day: datetime.date) -> str:
    """The figures as the doc states them."""
    minutes, seconds = divmod(round(run.seconds), 60)
    skipped = f", {run.skipped:,} skipped (each saying what it needs)" if run.skipped else ""
    return (
        f"`make test` after it: ruff and mypy (seconds with warm caches), then pytest: "
        f"{run.tests:,} tests, {run.passed:,} passed{skipped}, in {minutes} min {seconds:02d} s "
        f"(measured {day.isoformat()} at commit {commit} on this machine; "
        f"`python -m tests.suite_figures --write` measures it again and rewrites this line)."
    )


def rewritten(document: str, text: str) -> str:
    """The document with the text between the markers replaced."""
    head, start, rest = document.partition(START)
    _old, end, tail = rest.partition(END)
    if not start or not end:
        raise ValueError(f"the markers {START} and {END} are not both in the document")
    return f"{head}{START}\n{text}\n{END}{tail}"


def commit() -> str:
    described = subprocess.run(
        ["git", "describe", "--always", "--dirty", "--abbrev=7"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    return described.stdout.strip() or "unknown"


def measure(pytest_args: list[str]) -> tuple[SuiteRun, int]:
    """Run pytest (its output streams through); the counts and pytest's exit code."""
    with tempfile.TemporaryDirectory() as folder:
        report = Path(folder) / "junit.xml"
        began = time.monotonic()
        code = subprocess.call(
            [sys.executable, "-m", "pytest", "-q", f"--junitxml={report}", *pytest_args],
            cwd=ROOT,
        )
        seconds = time.monotonic() - began
        if not report.is_file():
            raise SystemExit(f"suite_figures: pytest wrote no report (exit {code})")
        return counted(report.read_text(), seconds), code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--write", action="store_true", help=f"rewrite the figures in {INSTALL_DOC.name}"
    )
    parser.add_argument("pytest_args", nargs="*", help="passed on to pytest (after --)")
    args = parser.parse_args(argv)
    run, code = measure(args.pytest_args)
    text = sentence(run, commit(), datetime.date.today())
    print(text)
    if code != 0:
        print(f"suite_figures: pytest exited {code}; nothing written", file=sys.stderr)
        return code
    if args.write:
        INSTALL_DOC.write_text(rewritten(INSTALL_DOC.read_text(), text))
        print(f"wrote {INSTALL_DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
