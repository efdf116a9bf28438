"""One table of every benchmark's figures, its goal, the peer measured in the same run, and the
verdict, read from the JSON the benchmarks wrote under bench/results/.

    python -m bench.summary [--results DIR] [--write-docs [--doc PATH]]

A benchmark whose JSON is missing is listed as not run; one whose JSON lacks a figure this reads
is listed as unreadable. The table is printed and written to bench/results/summary.json.
`--write-docs` rewrites the benchmark table of docs/benchmarks.md (between its `bench-table` markers): the
figure of every benchmark that has results is replaced, the command column is kept, and a row
whose benchmark has no results here stays as it was written.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Generic, TypeVar

from pydantic import ValidationError

from bench import records
from bench.records import read_record
from bench.summary_readers import (
    GOALS,
    Figure,
    read_append,
    read_as_of,
    read_blobs,
    read_decide,
    read_fixture_step,
    read_memory,
    read_plan,
    read_raw,
    read_render,
    read_rollout,
    read_service,
    read_stream,
    read_versus,
)

Result = TypeVar("Result")
RESULTS_DIR = Path(__file__).resolve().parent / "results"
BENCHMARKS_DOC = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
START_MARKER = "<!-- bench-table:start -->"
END_MARKER = "<!-- bench-table:end -->"
TABLE_HEADER = (
    "| benchmark | command | figure on this machine (2 cores) |",
    "| --- | --- | --- |",
)


@dataclass
class Row:
    """One printed line: a figure with its goal and verdict, or a benchmark not run."""

    benchmark: str
    label: str
    command: str
    status: str  # "run", "not run" or "unreadable"
    source: str
    figure: str = ""
    peer: str = ""
    goal: str = ""
    verdict: str = ""
    met: bool | None = None
    written: str = ""  # when the result file was written (UTC), so a stale figure shows


def judged(bench: Bench[Any], figure: Figure, source: str) -> Row:
    """A figure with its goal's text and verdict."""
    goal = GOALS[figure.goal] if figure.goal else None
    verdict, met = figure.verdict, figure.met
    if verdict is None:
        if goal is not None and figure.value is not None:
            verdict, met = goal.verdict(figure.value), goal.holds(figure.value)
        else:
            verdict = "-" if goal is None else "not measured"
    return Row(
        benchmark=bench.key,
        label=figure.label,
        command=bench.command,
        status="run",
        source=source,
        figure=figure.figure,
        peer=figure.peer or "-",
        goal=goal.text if goal else "-",
        verdict=verdict,
        met=met,
    )


# --- the benchmarks ------------------------------------------------------------------------


@dataclass(frozen=True)
class Bench(Generic[Result]):
    """A benchmark: how it is run, the file it writes, its record, and how its figures are read."""

    key: str
    command: str  # as in the table's command column (module, then subcommand)
    pattern: str  # the file name under bench/results/ (a glob: the newest match is read)
    record: type[Result]  # what the benchmark writes (bench/records.py)
    read: Callable[[Result], list[Figure]]
    goals: tuple[str, ...] = field(default=())
    notes: str = ""  # where bench/README.md explains the figures (why a goal is missed)

    @property
    def invocation(self) -> str:
        """The module and subcommand (`bench.bench_store raw`), which names a table row."""
        return invocation(self.command) or self.command


BENCHES: tuple[Bench[Any], ...] = (
    Bench(
        "render",
        "python -m bench.bench_render",
        "render.json",
        records.RenderResult,
        read_render,
        ("render",),
    ),
    Bench(
        "decide",
        "python -m bench.bench_decide",
        "decide.json",
        records.DecideResult,
        read_decide,
        ("decide", "decide_hypotheses"),
    ),
    Bench(
        "fixture_step",
        "python -m bench.bench_fixture_step",
        "fixture_step.json",
        records.FixtureStepResult,
        read_fixture_step,
        ("fixture_step",),
        notes="../bench/README.md#the-fixture-step",
    ),
    Bench(
        "stream",
        "python -m bench.bench_stream",
        "stream.json",
        records.StreamResult,
        read_stream,
        ("stream",),
    ),
    Bench(
        "plan",
        "python -m bench.bench_plan",
        "bench_plan.json",
        records.PlanResult,
        read_plan,
        ("plan",),
    ),
    Bench(
        "rollout",
        "python -m bench.bench_rollout",
        "bench_rollout.json",
        records.RolloutBenchResult,
        read_rollout,
        ("rollout", "rollout_planner"),
    ),
    Bench(
        "store-append",
        "python -m bench.bench_store append --postgres URL",
        "store-append.json",
        records.AppendResult,
        read_append,
        ("append",),
    ),
    Bench(
        "store-as-of",
        "python -m bench.bench_store as-of --postgres URL",
        "store-as-of.json",
        records.AsOfResult,
        read_as_of,
        ("as_of",),
        notes="../bench/README.md#as_of",
    ),
    Bench(
        "store-versus",
        "python -m bench.bench_store versus --postgres URL",
        "store-versus.json",
        records.VersusResult,
        read_versus,
        ("versus",),
        notes="../bench/README.md#appending-against-the-eventsourcing-library",
    ),
    Bench(
        "store-raw",
        "python -m bench.bench_store raw",
        "store-raw.json",
        records.RawResult,
        read_raw,
        ("raw",),
        notes="../bench/README.md#raw-batches",
    ),
    Bench(
        "blobs",
        "python -m bench.bench_blobs --postgres URL",
        "blobs.json",
        records.BlobsResult,
        read_blobs,
        notes="operations.md#running-on-several-hosts",
    ),
    Bench(
        "memory",
        "python -m bench.bench_memory",
        "memory.json",
        records.MemoryResult,
        read_memory,
        ("memory",),
        notes="operations.md#limits-backpressure-and-failures",
    ),
    Bench(
        "service",
        "python -m bench.bench_service --postgres URL --ramp 6,8,10,12",
        "service-*.json",
        records.ServiceResult,
        read_service,
        ("service_one_worker", "service_two_workers"),
        notes="../bench/README.md",
    ),
)


def invocation(command: str) -> str | None:
    """`bench.bench_store raw` from a command such as `python -m bench.bench_store raw ...`."""
    found = re.search(r"python -m (bench\.\w+)(?: (append|as-of|versus|raw)\b)?", command)
    if found is None:
        return None
    return " ".join(part for part in found.groups() if part)


def result_file(results: Path, bench: Bench[Any]) -> Path | None:
    """The file the benchmark wrote (the newest, when its name carries the time), or None."""
    found = sorted(results.glob(bench.pattern), key=lambda path: (path.stat().st_mtime, path.name))
    return found[-1] if found else None


def rows_of(bench: Bench[Any], results: Path) -> list[Row]:
    """The benchmark's rows: its figures judged, or one row saying it was not run or cannot be
    read (a file of another shape: the benchmark changed, or the file was cut short)."""
    path = result_file(results, bench)
    goal = "; ".join(GOALS[key].text for key in bench.goals) or "-"
    if path is None:
        return [
            Row(bench.key, bench.key, bench.command, "not run", "", goal=goal, verdict="not run")
        ]
    try:
        figures = bench.read(read_record(bench.record, path))
    except ValidationError as error:
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "the file"
        why = (
            f"unreadable: not a {bench.record.__name__} ({error.error_count()} errors; "
            f"{where}: {first['msg']})"
        )
        return [
            Row(
                bench.key, bench.key, bench.command, "unreadable", path.name, goal=goal, verdict=why
            )
        ]
    except (KeyError, ZeroDivisionError) as error:  # a record without the figure a goal reads
        why = f"unreadable: {type(error).__name__} {error}"
        return [
            Row(
                bench.key, bench.key, bench.command, "unreadable", path.name, goal=goal, verdict=why
            )
        ]
    written = datetime.fromtimestamp(path.stat().st_mtime, UTC).strftime("%Y-%m-%d %H:%M")
    rows = [judged(bench, figure, path.name) for figure in figures]
    for row in rows:
        row.written = written
    return rows


def summary(results: Path = RESULTS_DIR) -> list[Row]:
    """Every benchmark's rows, in the order `make bench` runs them."""
    return [row for bench in BENCHES for row in rows_of(bench, results)]


# --- output ---------------------------------------------------------------------------------


def table(rows: Sequence[Row]) -> str:
    """The rows as one plain-text table."""
    header = ("benchmark", "figure", "peer in the same run", "goal", "verdict", "written (UTC)")
    lines = [
        (
            row.label,
            row.figure or row.status,
            row.peer or "-",
            row.goal or "-",
            row.verdict,
            row.written or "-",
        )
        for row in rows
    ]
    widths = [max(len(line[i]) for line in [header, *lines]) for i in range(len(header))]
    rule = "-+-".join("-" * width for width in widths)
    text = [
        " | ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True))
        for line in [header, *lines]
    ]
    return "\n".join([text[0], rule, *text[1:]])


def doc_figure(bench: Bench[Any], rows: Sequence[Row]) -> str:
    """A benchmark's figure cell in the table: each figure, its peer, its goal and verdict
    (one line each), then where its figures are explained."""
    parts = []
    for row in rows:
        text = f"{row.label}: {row.figure}" if len(rows) > 1 else row.figure
        if row.peer and row.peer != "-":
            text += f"; same run: {row.peer}"
        if row.goal and row.goal != "-":
            text += f" (goal {row.goal}: {row.verdict})"
        parts.append(text)
    if bench.notes:
        parts[-1] += f" ([notes]({bench.notes}))"
    return "<br>".join(parts).replace("|", "/")


def split_row(line: str) -> list[str]:
    """The cells of a Markdown table row."""
    return [cell.strip() for cell in line.strip().strip("|").split(" | ")]


def doc_table(lines: Sequence[str], rows: Sequence[Row]) -> list[str]:
    """The table's new lines: a row of a benchmark with results gets its figure from them; the
    others stay as written; a benchmark with results and no row gets one at the end."""
    by_bench: dict[str, list[Row]] = {}
    for row in rows:
        if row.status == "run":
            by_bench.setdefault(row.benchmark, []).append(row)
    benches = {bench.invocation: bench for bench in BENCHES}
    out, seen = list(TABLE_HEADER), set()
    for line in lines:
        if not line.strip() or line.strip() in TABLE_HEADER:
            continue
        cells = split_row(line)
        bench = benches.get(invocation(cells[1]) or "") if len(cells) == 3 else None
        if bench is not None:
            seen.add(bench.key)
            if bench.key in by_bench:
                line = f"| {cells[0]} | {cells[1]} | {doc_figure(bench, by_bench[bench.key])} |"
        out.append(line.rstrip())
    for bench in BENCHES:
        if bench.key in by_bench and bench.key not in seen:
            label = by_bench[bench.key][0].label
            out.append(
                f"| {label} | `{bench.command}` | {doc_figure(bench, by_bench[bench.key])} |"
            )
    return out


def rewrite_table(text: str, rows: Sequence[Row]) -> str:
    """`text` with the table between the markers regenerated; everything else unchanged."""
    start, end = text.find(START_MARKER), text.find(END_MARKER)
    if start < 0 or end < start:
        raise ValueError(f"the page has no {START_MARKER} ... {END_MARKER} block")
    body_start = start + len(START_MARKER)
    old = text[body_start:end].strip("\n").splitlines()
    new = "\n".join(doc_table(old, rows))
    return f"{text[:body_start]}\n{new}\n{text[end:]}"


def main(argv: list[str] | None = None) -> None:
    """Print the table, write summary.json, and with --write-docs the table of docs/benchmarks.md."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--results", type=Path, default=RESULTS_DIR, help="where the JSON is")
    parser.add_argument(
        "--write-docs",
        action="store_true",
        help="regenerate the benchmark table of docs/benchmarks.md",
    )
    parser.add_argument(
        "--doc", type=Path, default=BENCHMARKS_DOC, help="the page holding the table"
    )
    args = parser.parse_args(argv)
    rows = summary(args.results)
    print(table(rows))
    args.results.mkdir(parents=True, exist_ok=True)
    path = args.results / "summary.json"
    path.write_text(json.dumps({"rows": [asdict(row) for row in rows]}, indent=2) + "\n")
    print(f"wrote {path}")
    if args.write_docs:
        before = args.doc.read_text()
        try:
            after = rewrite_table(before, rows)
        except ValueError as error:
            sys.exit(f"{args.doc}: {error}")
        if after != before:
            args.doc.write_text(after)
        print(f"{'rewrote' if after != before else 'unchanged:'} {args.doc}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
