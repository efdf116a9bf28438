"""One table of every benchmark's figures, its goal, the peer measured in the same run, and the
verdict, read from the JSON the benchmarks wrote under bench/results/.

    python -m bench.summary [--results DIR] [--write-readme [--readme PATH]]

A benchmark whose JSON is missing is listed as not run; one whose JSON lacks a figure this reads
is listed as unreadable. The table is printed and written to bench/results/summary.json.
`--write-readme` rewrites the README's benchmark table (between its `bench-table` markers): the
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
from typing import Any

RESULTS_DIR = Path(__file__).resolve().parent / "results"
README = Path(__file__).resolve().parent.parent / "README.md"
START_MARKER = "<!-- bench-table:start -->"
END_MARKER = "<!-- bench-table:end -->"
README_HEADER = (
    "| benchmark | command | figure on this machine (2 cores) |",
    "| --- | --- | --- |",
)


@dataclass(frozen=True)
class Goal:
    """A bound on one figure: `value <op> bound`, in `unit`."""

    text: str
    op: str  # "<", "<=", ">" or ">="
    bound: float
    unit: str

    def holds(self, value: float) -> bool:
        """Whether `value` meets the goal."""
        return {
            "<": value < self.bound,
            "<=": value <= self.bound,
            ">": value > self.bound,
            ">=": value >= self.bound,
        }[self.op]

    def verdict(self, value: float) -> str:
        """'met', or 'missed by' the distance to the bound, in the unit and in percent."""
        if self.holds(value):
            return "met"
        gap = abs(value - self.bound)
        if gap == 0:
            return f"missed: at the bound, {number(value)}{self.unit}"
        return f"missed by {number(gap)}{self.unit} ({gap / self.bound:.0%})"


# The goals, in one place: issue 11 ("Real time end to end, ahead of the reference event store,
# and bounded storage": fixture step, appending against `eventsourcing`, as_of, raw batches, the
# service end to end) and the goals the README's benchmark table already held (render, decide,
# append, planner, rollout, memory budget).
GOALS: dict[str, Goal] = {
    "render": Goal(">= 30 frames/s", ">=", 30.0, " frames/s"),
    "decide": Goal("< 10 ms", "<", 10.0, " ms"),
    "decide_hypotheses": Goal("<= 1.5x the live tracks alone", "<=", 1.5, "x"),
    "fixture_step": Goal("median <= 10 ms per batch at 100k voxels", "<=", 10.0, " ms"),
    "plan": Goal("median < 50 ms per decision", "<", 50.0, " ms"),
    "rollout": Goal("< 5 min", "<", 300.0, " s"),
    "rollout_planner": Goal("median < 50 ms per decision", "<", 50.0, " ms"),
    "append": Goal("> 20,000 events/s", ">", 20_000.0, " events/s"),
    "as_of": Goal("median < 20 ms at 1,000,000 events", "<", 20.0, " ms"),
    "versus": Goal("ours/theirs >= 1 (ahead at every batch size)", ">=", 1.0, ""),
    "raw": Goal("<= 0.300 MB per frame", "<=", 0.3, " MB"),
    "memory": Goal("peak <= 1 GB (1,024 MB)", "<=", 1024.0, " MB"),
    "service_one_worker": Goal(
        "one worker keeps up with 30 frames/s, POST-to-done p99 < 200 ms", ">=", 30.0, "/s"
    ),
    "service_p99": Goal("p99 < 200 ms", "<", 200.0, " ms"),
    "service_two_workers": Goal(">= 1.8x one worker (2 scenes each)", ">=", 1.8, "x"),
}
AS_OF_EVENTS = 1_000_000  # the scene size the as_of goal is stated at
FIXTURE_VOXELS = 100_000  # the map size the fixture step's goal is stated at


def number(value: float) -> str:
    """A figure with as many digits as it deserves: 20,000 / 173 / 7.3 / 0.32."""
    size = abs(value)
    if size >= 1000:
        return f"{value:,.0f}"
    if size >= 100:
        return f"{value:.0f}"
    if size >= 1:
        return f"{value:.1f}"
    if size >= 0.1:
        return f"{value:.2f}"
    return f"{value:.3f}"


@dataclass
class Figure:
    """One line of the table, as a benchmark's reader produces it."""

    label: str
    figure: str
    peer: str = ""
    goal: str | None = None  # a key of GOALS
    value: float | None = None  # what the goal bounds
    verdict: str | None = None  # a reader's own verdict (goals that bound several figures)
    met: bool | None = None


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


def judged(bench: Bench, figure: Figure, source: str) -> Row:
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


# --- the readers: one per result file, keys as each benchmark writes them -----------------


def read_render(data: dict[str, Any]) -> list[Figure]:
    one, every = data["one_thread"]["fps"], data["all_threads"]["fps"]
    return [
        Figure(
            "render + detect, 640x480",
            f"{number(one)} frames/s on one thread, {number(every)} on all",
            goal="render",
            value=one,
        )
    ]


def read_decide(data: dict[str, Any]) -> list[Figure]:
    conditions = data["conditions"]
    live = conditions["500 live tracks"]
    base = live["decide_evolve_median_ms"]
    figures = [
        Figure(
            "decide + evolve, 20 masks, 500 live tracks",
            f"median {number(base)} ms, p90 {number(live['decide_evolve_p90_ms'])} ms "
            f"(decide {number(live['decide_median_ms'])}, "
            f"evolve {number(live['evolve_median_ms'])})",
            goal="decide",
            value=base,
        )
    ]
    others = {name: row for name, row in conditions.items() if name != "500 live tracks"}
    if others:
        worst = max(row["ratio_to_live_only"] for row in others.values())
        figures.append(
            Figure(
                "decide + evolve with retired or stale hypotheses in memory",
                ", ".join(
                    f"{name}: {number(row['decide_evolve_median_ms'])} ms "
                    f"({row['ratio_to_live_only']:.2f}x)"
                    for name, row in others.items()
                ),
                peer=f"500 live tracks alone: {number(base)} ms",
                goal="decide_hypotheses",
                value=worst,
            )
        )
    return figures


def read_fixture_step(data: dict[str, Any]) -> list[Figure]:
    figures = []
    for name, goal in (("house", "fixture_step"), ("suite", None)):
        row = data["conditions"].get(name)
        if row is None:
            continue
        kept, full, cpu = row["incremental"], row["full"], row["incremental_cpu"]
        low, high = row["voxels"]
        figure = Figure(
            f"fixture step per batch, {name} ({number(low)}-{number(high)} voxels)",
            f"median {kept['median_ms']:.1f} ms, p90 {kept['p90_ms']:.1f}, max "
            f"{kept['max_ms']:.1f} (CPU median {cpu['median_ms']:.1f})",
            peer=f"full re-clustering {number(full['median_ms'])} ms "
            f"({row['median_ratio_full_to_incremental']:.1f}x)",
            goal=goal,
            value=kept["median_ms"],
        )
        if goal and low < FIXTURE_VOXELS:
            figure.verdict = f"not judged: {number(low)} voxels, the goal is at 100k"
        figures.append(figure)
    return figures


def read_plan(data: dict[str, Any]) -> list[Figure]:
    evidence = data["evidence"]
    return [
        Figure(
            "planner decision, 20 m x 20 m at 5 cm",
            f"median {number(data['ms_per_decision_median'])} ms, p90 "
            f"{number(data['ms_per_decision_p90'])}, max {number(data['ms_per_decision_max'])}; "
            f"occupancy evidence {evidence['bytes_per_batch_median'] / 1000:.1f} KB per frame, "
            f"{number(evidence['evidence_ms_per_frame_median'])} ms",
            goal="plan",
            value=data["ms_per_decision_median"],
        )
    ]


def read_rollout(data: dict[str, Any]) -> list[Figure]:
    return [
        Figure(
            f"autonomous rollout, {data['scenario']} ({number(data['area_m2'])} m², "
            f"seed {data['seed']})",
            f"{number(data['rollout_s'])} s: {data['keyframes']} keyframes, "
            f"{data['inspections']} inspections, {number(data['path_m'])} m "
            f"({data['stop_reason']})",
            goal="rollout",
            value=data["rollout_s"],
        ),
        Figure(
            "planner per decision during the rollout",
            f"median {number(data['planner_ms_median'])} ms, p90 "
            f"{number(data['planner_ms_p90'])}, max {number(data['planner_ms_max'])} over "
            f"{data['decisions']} decisions",
            goal="rollout_planner",
            value=data["planner_ms_median"],
        ),
    ]


BACKENDS = {"sqlite": "SQLite", "postgres": "PostgreSQL"}


def read_append(data: dict[str, Any]) -> list[Figure]:
    return [
        Figure(
            f"append, {BACKENDS[name]}, batches of {data['batch']}",
            f"{number(data[name]['events_per_s'])} events/s",
            goal="append",
            value=data[name]["events_per_s"],
        )
        for name in BACKENDS
        if name in data
    ]


def read_as_of(data: dict[str, Any]) -> list[Figure]:
    figures = []
    for name in (name for name in BACKENDS if name in data):
        row = data[name]
        figure = Figure(
            f"as_of, {BACKENDS[name]}, {number(row['head_seq'])} events",
            f"median {number(row['as_of_median_ms'])} ms, p90 {number(row['as_of_p90_ms'])}; "
            f"snapshots {number(row['snapshot_bytes'] / row['head_seq'])} bytes per event",
            peer=f"full replay {number(row['full_replay_ms'] / 1000)} s "
            f"({number(row['speedup'])}x)",
            goal="as_of",
            value=row["as_of_median_ms"],
        )
        if data["events"] < AS_OF_EVENTS:
            figure.verdict = f"not judged: {number(data['events'])} events, the goal is at 1M"
        figures.append(figure)
    return figures


def read_versus(data: dict[str, Any]) -> list[Figure]:
    figures = []
    for name in (name for name in BACKENDS if name in data):
        for batch, row in data[name].items():
            figures.append(
                Figure(
                    f"append vs {data['peer']}, {BACKENDS[name]}, batches of {batch}",
                    f"ours {number(row['ours_events_per_s'])} events/s: {row['ratio']:.2f} "
                    f"(per track {row['ratio_per_track']:.2f})",
                    peer=f"{number(row['eventsourcing_events_per_s'])}/s one aggregate, "
                    f"{number(row['eventsourcing_per_track_events_per_s'])}/s one per track",
                    goal="versus",
                    value=row["ratio"],
                )
            )
    return figures


def read_raw(data: dict[str, Any]) -> list[Figure]:
    compact = data["compact_bytes_per_frame"] / 1e6
    return [
        Figure(
            "raw batch kept per 640x480 frame",
            f"{compact:.3f} MB compact (max {data['compact_max_bytes_per_frame'] / 1e6:.3f}); "
            f"{data['compact_raw_bytes_per_event'] / 1000:.1f} kB per event; encode "
            f"{number(data['encode_ms_median'])} ms, decode {number(data['decode_ms_median'])} ms",
            peer=f"JSON with base64 depth {data['json_base64_bytes_per_frame'] / 1e6:.3f} MB "
            f"(x{data['ratio']:.2f})",
            goal="raw",
            value=round(compact, 3),
        )
    ]


def read_blobs(data: dict[str, Any]) -> list[Figure]:
    figures = []
    for body, row in data["bodies"].items():
        table, folder = row["backends"]["postgres+table"], row["backends"]["postgres+folder"]
        figures.append(
            Figure(
                f"raw batch storage, PostgreSQL table, {body} "
                f"({row['mean_blob_bytes'] / 1e6:.2f} MB)",
                f"put + enqueue {number(table['put_enqueue_ms_median'])} ms, "
                f"get {table['get_ms_median']:.2f} ms",
                peer=f"folder {number(folder['put_enqueue_ms_median'])} / "
                f"{folder['get_ms_median']:.2f} ms (table/folder "
                f"{table['put_enqueue_vs_folder']:.2f} / {table['get_vs_folder']:.1f})",
            )
        )
    return figures


def read_memory(data: dict[str, Any]) -> list[Figure]:
    cases = data["cases"]
    worst = max(
        cases, key=lambda name: max(cases[name]["api_peak_mb"], cases[name]["worker_peak_mb"])
    )
    api = max(case["api_peak_mb"] for case in cases.values())
    worker = max(case["worker_peak_mb"] for case in cases.values())
    return [
        Figure(
            "peak memory of the largest accepted batches",
            f"at most {number(max(api, worker))} MB (API {number(api)}, worker "
            f"{number(worker)}; largest: {worst})",
            goal="memory",
            value=max(api, worker),
        )
    ]


def read_service(data: dict[str, Any]) -> list[Figure]:
    configs, goals = data["configs"], data["goals"]
    figures = []
    at_rate = goals.get("one_worker_at_rate")
    ramp = goals.get("one_worker_sustains_per_s")
    if at_rate is None:
        figures.append(
            Figure(
                "service end to end, one worker, one scene",
                "not measured in this run",
                goal="service_one_worker",
            )
        )
    else:
        one = configs[at_rate["config"]]
        text = (
            f"({at_rate['config']}) at {at_rate['rate']:g}/s: {number(one['throughput'])} "
            f"done/s, p99 {number(one['done_p99_ms'])} ms"
        )
        sustained = ramp["highest_sustained"] if ramp else None
        if ramp:
            text += (
                "; sustains none of " + ", ".join(f"{r:g}" for r in ramp["rates_tried"]) + "/s"
                if sustained is None
                else f"; sustains {sustained:g}/s, p99 {number(ramp['done_p99_ms'])} ms"
            )
        if at_rate["met"]:
            verdict = "met"
        else:
            # The highest rate of the ramp it kept up with, else what it did at the goal's rate.
            kept = sustained if sustained is not None else one["throughput"]
            shown = f"{sustained:g}" if sustained is not None else number(kept)
            goal = GOALS["service_one_worker"]
            verdict = f"missed: {shown}/s ({(goal.bound - kept) / goal.bound:.0%} short)"
            if at_rate["done_p99_ms"] >= GOALS["service_p99"].bound:
                verdict += f", p99 {number(at_rate['done_p99_ms'])} ms at {at_rate['rate']:g}/s"
        figures.append(
            Figure(
                "service end to end, one worker, one scene",
                text,
                goal="service_one_worker",
                verdict=verdict,
                met=bool(at_rate["met"]),
            )
        )
    scaling = goals.get("two_workers_scaling")
    if scaling is None:
        figures.append(
            Figure(
                "service end to end, two workers on two scenes",
                "not measured in this run (needs --postgres)",
                goal="service_two_workers",
            )
        )
    else:
        bound = goals.get("cpu_bound", {})
        text = f"(c) {number(configs['c']['throughput'])} done/s: {scaling['ratio']:.2f}x"
        if bound:
            text += (
                f"; the CPU bound allows {bound['two_worker_ratio_max']:.2f}x "
                f"({number(bound['worker_cpu_ms_per_batch'])} ms of worker CPU and "
                f"{number(bound['api_cpu_ms_per_batch'])} ms of API CPU per batch, "
                f"{bound['cores']} cores)"
            )
        figures.append(
            Figure(
                "service end to end, two workers on two scenes",
                text,
                peer=f"(d) one worker, two scenes: {number(configs['d']['throughput'])} done/s",
                goal="service_two_workers",
                value=scaling["ratio"],
            )
        )
    return figures


# --- the benchmarks ------------------------------------------------------------------------


@dataclass(frozen=True)
class Bench:
    """A benchmark: how it is run, the file it writes, and how its figures are read."""

    key: str
    command: str  # as in the README's command column (module, then subcommand)
    pattern: str  # the file name under bench/results/ (a glob: the newest match is read)
    read: Callable[[dict[str, Any]], list[Figure]]
    goals: tuple[str, ...] = field(default=())
    notes: str = ""  # where the README explains the figures (why a goal is missed)

    @property
    def invocation(self) -> str:
        """The module and subcommand (`bench.bench_store raw`), which names a README row."""
        return invocation(self.command) or self.command


BENCHES: tuple[Bench, ...] = (
    Bench("render", "python -m bench.bench_render", "render.json", read_render, ("render",)),
    Bench(
        "decide",
        "python -m bench.bench_decide",
        "decide.json",
        read_decide,
        ("decide", "decide_hypotheses"),
    ),
    Bench(
        "fixture_step",
        "python -m bench.bench_fixture_step",
        "fixture_step.json",
        read_fixture_step,
        ("fixture_step",),
        notes="bench/README.md#the-fixture-step",
    ),
    Bench("plan", "python -m bench.bench_plan", "bench_plan.json", read_plan, ("plan",)),
    Bench(
        "rollout",
        "python -m bench.bench_rollout",
        "bench_rollout.json",
        read_rollout,
        ("rollout", "rollout_planner"),
    ),
    Bench(
        "store-append",
        "python -m bench.bench_store append --postgres URL",
        "store-append.json",
        read_append,
        ("append",),
    ),
    Bench(
        "store-as-of",
        "python -m bench.bench_store as-of --postgres URL",
        "store-as-of.json",
        read_as_of,
        ("as_of",),
        notes="bench/README.md#as_of",
    ),
    Bench(
        "store-versus",
        "python -m bench.bench_store versus --postgres URL",
        "store-versus.json",
        read_versus,
        ("versus",),
        notes="bench/README.md#appending-against-the-eventsourcing-library",
    ),
    Bench(
        "store-raw",
        "python -m bench.bench_store raw",
        "store-raw.json",
        read_raw,
        ("raw",),
        notes="bench/README.md#raw-batches",
    ),
    Bench(
        "blobs",
        "python -m bench.bench_blobs --postgres URL",
        "blobs.json",
        read_blobs,
        notes="#running-on-several-hosts",
    ),
    Bench(
        "memory",
        "python -m bench.bench_memory",
        "memory.json",
        read_memory,
        ("memory",),
        notes="#limits-backpressure-and-failures",
    ),
    Bench(
        "service",
        "python -m bench.bench_service --postgres URL --ramp 6,8,10,12",
        "service-*.json",
        read_service,
        ("service_one_worker", "service_two_workers"),
        notes="bench/README.md",
    ),
)


def invocation(command: str) -> str | None:
    """`bench.bench_store raw` from a command such as `python -m bench.bench_store raw ...`."""
    found = re.search(r"python -m (bench\.\w+)(?: (append|as-of|versus|raw)\b)?", command)
    if found is None:
        return None
    return " ".join(part for part in found.groups() if part)


def result_file(results: Path, bench: Bench) -> Path | None:
    """The file the benchmark wrote (the newest, when its name carries the time), or None."""
    found = sorted(results.glob(bench.pattern), key=lambda path: (path.stat().st_mtime, path.name))
    return found[-1] if found else None


def rows_of(bench: Bench, results: Path) -> list[Row]:
    """The benchmark's rows: its figures judged, or one row saying it was not run or cannot be
    read (a file of another shape: the benchmark changed, or the file was cut short)."""
    path = result_file(results, bench)
    goal = "; ".join(GOALS[key].text for key in bench.goals) or "-"
    if path is None:
        return [
            Row(bench.key, bench.key, bench.command, "not run", "", goal=goal, verdict="not run")
        ]
    try:
        figures = bench.read(json.loads(path.read_text()))
    except (KeyError, TypeError, ValueError, IndexError, ZeroDivisionError) as error:
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


def readme_figure(bench: Bench, rows: Sequence[Row]) -> str:
    """A benchmark's figure cell in the README: each figure, its peer, its goal and verdict
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


def readme_table(lines: Sequence[str], rows: Sequence[Row]) -> list[str]:
    """The table's new lines: a row of a benchmark with results gets its figure from them; the
    others stay as written; a benchmark with results and no row gets one at the end."""
    by_bench: dict[str, list[Row]] = {}
    for row in rows:
        if row.status == "run":
            by_bench.setdefault(row.benchmark, []).append(row)
    benches = {bench.invocation: bench for bench in BENCHES}
    out, seen = list(README_HEADER), set()
    for line in lines:
        if not line.strip() or line.strip() in README_HEADER:
            continue
        cells = split_row(line)
        bench = benches.get(invocation(cells[1]) or "") if len(cells) == 3 else None
        if bench is not None:
            seen.add(bench.key)
            if bench.key in by_bench:
                line = f"| {cells[0]} | {cells[1]} | {readme_figure(bench, by_bench[bench.key])} |"
        out.append(line.rstrip())
    for bench in BENCHES:
        if bench.key in by_bench and bench.key not in seen:
            label = by_bench[bench.key][0].label
            out.append(
                f"| {label} | `{bench.command}` | {readme_figure(bench, by_bench[bench.key])} |"
            )
    return out


def rewrite_readme(text: str, rows: Sequence[Row]) -> str:
    """`text` with the table between the markers regenerated; everything else unchanged."""
    start, end = text.find(START_MARKER), text.find(END_MARKER)
    if start < 0 or end < start:
        raise ValueError(f"the README has no {START_MARKER} ... {END_MARKER} block")
    body_start = start + len(START_MARKER)
    old = text[body_start:end].strip("\n").splitlines()
    new = "\n".join(readme_table(old, rows))
    return f"{text[:body_start]}\n{new}\n{text[end:]}"


def main(argv: list[str] | None = None) -> None:
    """Print the table, write summary.json, and with --write-readme the README's table."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--results", type=Path, default=RESULTS_DIR, help="where the JSON is")
    parser.add_argument("--write-readme", action="store_true", help="regenerate the README table")
    parser.add_argument("--readme", type=Path, default=README)
    args = parser.parse_args(argv)
    rows = summary(args.results)
    print(table(rows))
    args.results.mkdir(parents=True, exist_ok=True)
    path = args.results / "summary.json"
    path.write_text(json.dumps({"rows": [asdict(row) for row in rows]}, indent=2) + "\n")
    print(f"wrote {path}")
    if args.write_readme:
        before = args.readme.read_text()
        try:
            after = rewrite_readme(before, rows)
        except ValueError as error:
            sys.exit(f"{args.readme}: {error}")
        if after != before:
            args.readme.write_text(after)
        print(f"{'rewrote' if after != before else 'unchanged:'} {args.readme}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
