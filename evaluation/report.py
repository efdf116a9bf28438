"""Reports of a protocol run: results.json, table.md in the paper's layout, and PNG figures."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no screen
import matplotlib.pyplot as plt

from evaluation.metrics import mean_std
from evaluation.tables import (
    PAPER_SCENARIO,
    READINGS,
    SUBJECT,
    latency_section,
    methods_in_order,
    per_scenario_tables,
    pooled,
    ran,
    ratio_of,
    readings_note,
    shortfalls,
    table,
    unavailable_note,
)
from evaluation.world_intervals import interval_table, intervals_json

REPO = Path(__file__).resolve().parents[1]


def code_version() -> str:
    """The git commit of the code that produced the figures (with -dirty when uncommitted)."""
    try:
        described = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=12"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        )
        return described.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def figures(protocol: str, rows: Sequence[dict[str, Any]], out: Path) -> list[Path]:
    """Bar charts: IDF1 and event recall per method, false absence; or F1 per scene and method."""
    rows = ran(rows)
    methods = methods_in_order(rows)
    written = []
    if protocol == "dynamic":
        idf1 = [mean_std([r["idf1"] for r in rows if r["method"] == m])[0] for m in methods]
        recall = {
            name: [ratio_of(pooled(rows, m, key, "events_total")) for m in methods]
            for name, key in (
                ("event recall", "events_recalled_identity"),
                ("event recall, lenient", "events_recalled"),
            )
        }
        written.append(
            _bars(
                out / "idf1_event_recall.png",
                methods,
                {"IDF1": idf1, **recall},
                "Identity and event recall",
            )
        )
        absence = {
            name: [ratio_of(pooled(rows, m, absent, eligible)) for m in methods]
            for name, absent, eligible in (
                (
                    "false absence",
                    "false_absent_checkpoints_identity",
                    "eligible_checkpoints_identity",
                ),
                (
                    "false absence, identity-agnostic (lenient)",
                    "false_absent_checkpoints",
                    "eligible_checkpoints",
                ),
            )
        }
        written.append(
            _bars(out / "false_absence.png", methods, absence, "False absence (lower is better)")
        )
    else:
        scenes = list(dict.fromkeys(r["scenario"] for r in rows))
        series = {
            m: [
                mean_std([r["f1"] for r in rows if r["method"] == m and r["scenario"] == s])[0]
                for s in scenes
            ]
            for m in methods
        }
        written.append(
            _bars(out / "fixture_f1_per_scene.png", scenes, series, "Coarse-fixture F1 per scene")
        )
    return written


def _bars(path: Path, groups: Sequence[str], series: dict[str, list[float]], title: str) -> Path:
    figure, axis = plt.subplots(
        figsize=(max(6.0, 1.1 * len(groups) * max(1, len(series)) / 1.5), 4.0)
    )
    width = 0.8 / len(series)
    for k, (name, values) in enumerate(series.items()):
        axis.bar([i + k * width for i in range(len(groups))], values, width, label=name)
    axis.set_xticks(
        [i + width * (len(series) - 1) / 2 for i in range(len(groups))],
        groups,
        rotation=30,
        ha="right",
    )
    axis.set_ylim(0, 1.05)
    axis.set_title(title)
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return path


def write_report(
    protocol: str,
    rows: Sequence[dict[str, Any]],
    out: Path,
    seeds: Sequence[int],
    params: Mapping[str, Any] | None = None,
    worlds: Mapping[str, Any] | None = None,
    scenario_overrides: Mapping[str, Any] | None = None,
) -> list[Path]:
    """results.json, table.md and the figures under `out`; `params`: the overrides of
    core/params.py every method ran with (none: its defaults); `worlds`: the generated split
    the run used (none: scenario files); `scenario_overrides`: fields merged into every world."""
    out.mkdir(parents=True, exist_ok=True)
    scenarios = {
        r["scenario"]: {"file": r["scenario_file"], "sha256": r["scenario_sha256"]} for r in rows
    }
    results = {
        "protocol": protocol,
        "code_version": code_version(),
        "seeds": list(seeds),
        "params": dict(params or {}),
        "generated_worlds": dict(worlds) if worlds else None,
        "scenario_overrides": dict(scenario_overrides or {}),
        "intervals": intervals_json(protocol, rows),
        # Which key of a run is each headline (strict) and which its lenient reading.
        "readings": (
            {reading.figure: reading.as_json() for reading in READINGS}
            if protocol == "dynamic"
            else {}
        ),
        "scenarios": scenarios,
        "runs": list(rows),
    }
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    runs = len({(r["scenario"], r["seed"]) for r in rows})
    header = (
        f"Mean ± sample std over {runs} scenario-seed runs (seeds {', '.join(map(str, seeds))}); "
        f"code {results['code_version']}; parameters: "
        + (
            f"core/params.py with {json.dumps(params, sort_keys=True)}"
            if params
            else "core/params.py"
        )
        + ".\n\n"
    )
    if scenario_overrides:
        header += (
            "Every world ran with these scenario fields overridden: "
            f"{json.dumps(scenario_overrides, sort_keys=True)}.\n\n"
        )
    if worlds:
        header += (
            f"Generated worlds: the {worlds['split']} split, {worlds['count']} worlds.\n\n"
            "## Every method, with intervals over worlds\n\n"
            + interval_table(protocol, rows)
            + "\n"
        )
    if protocol == "dynamic":
        text = "# Dynamic memory (the paper's Table 2)\n\n" + header + dynamic_text(rows)
    else:
        text = (
            "# Coarse fixtures (the paper's Table 1)\n\n"
            + header
            + table(protocol, rows)
            + "\n## Per scenario\n\n"
            + per_scenario_tables(protocol, rows)
        )
    (out / "table.md").write_text(text)
    return [out / "results.json", out / "table.md", *figures(protocol, rows, out)]


def dynamic_text(rows: Sequence[dict[str, Any]]) -> str:
    """Headline (hotel suite alone, as the paper), pooled table, latencies, shortfalls."""
    paper_rows = [r for r in rows if r["scenario"] == PAPER_SCENARIO]
    parts = []
    if paper_rows:
        parts.append(
            f"## Table 2: {PAPER_SCENARIO} alone, as the paper\n\n" + table("dynamic", paper_rows)
        )
    parts.append("## Pooled over every scenario\n\n" + table("dynamic", rows))
    parts.append(
        "Event R. counts scheduled changes reflected within the scenario's latency bound, from "
        "the first batch the change was observable.\n\n" + readings_note()
    )
    parts.append(
        "## Event latency (every run pooled, the strict Event R.)\n\n" + latency_section(rows)
    )
    parts.append(f"## Shortfalls of {SUBJECT}, with their traces\n\n" + shortfalls(rows))
    note = unavailable_note(rows)
    if note:
        parts.append("## Not run\n\n" + note)
    parts.append("## Per scenario\n\n" + per_scenario_tables("dynamic", rows))
    return "\n".join(parts)
