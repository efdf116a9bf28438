"""Reports of a protocol run: results.json, table.md in the paper's layout, and PNG figures."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no screen
import matplotlib.pyplot as plt

from evaluation.metrics import mean_std

REPO = Path(__file__).resolve().parents[1]
DYNAMIC_COLUMNS = (("idf1", "IDF1↑"), ("id_presence_f1", "ID-Pres.↑"), ("id_switches", "IDS↓"))
FIXTURE_COLUMNS = (
    ("precision", "P↑"),
    ("recall", "R↑"),
    ("f1", "F1↑"),
    ("center_error", "Err. [m]↓"),
    ("count_mae", "MAE↓"),
)


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


def cell(values: Sequence[float | None]) -> str:
    """mean ± sample std, the paper's format (.833±.029)."""
    numbers = [v for v in values if v is not None]
    if not numbers:
        return "-"
    mean, std = mean_std(numbers)
    return f"{_short(mean)}±{_short(std)}"


def _short(value: float) -> str:
    text = f"{value:.3f}"
    return text[1:] if text.startswith("0.") else text


def methods_in_order(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Methods in the order they ran."""
    return list(dict.fromkeys(row["method"] for row in rows))


def pooled(
    rows: Sequence[dict[str, Any]], method: str, numerator: str, denominator: str
) -> tuple[int, int]:
    """A method's counts summed over its runs (event recall and false absence are pooled)."""
    mine = [r for r in rows if r["method"] == method]
    return sum(r[numerator] for r in mine), sum(r[denominator] for r in mine)


def ratio_of(counts: tuple[int, int]) -> float:
    """numerator / denominator, 0 when there is nothing to count."""
    return counts[0] / counts[1] if counts[1] else 0.0


def table(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """The paper's table layout: one row per method, mean ± sample std over scenario-seed runs."""
    if protocol == "dynamic":
        header = "| Method | IDF1↑ | ID-Pres.↑ | IDS↓ | Event R.↑ | False abs.↓ |\n|---|---|---|---|---|---|\n"
        lines = []
        for method in methods_in_order(rows):
            mine = [r for r in rows if r["method"] == method]
            recalled, total = pooled(rows, method, "events_recalled", "events_total")
            absence = ratio_of(
                pooled(rows, method, "false_absent_checkpoints", "eligible_checkpoints")
            )
            cells = [cell([r[key] for r in mine]) for key, _ in DYNAMIC_COLUMNS]
            lines.append(
                f"| {method} | {' | '.join(cells)} | {recalled}/{total} | {_short(absence)} |"
            )
        return header + "\n".join(lines) + "\n"
    header = (
        "| Method | "
        + " | ".join(title for _, title in FIXTURE_COLUMNS)
        + " |\n|---|"
        + "---|" * len(FIXTURE_COLUMNS)
        + "\n"
    )
    lines = [
        f"| {method} | "
        + " | ".join(
            cell([r[key] for r in rows if r["method"] == method]) for key, _ in FIXTURE_COLUMNS
        )
        + " |"
        for method in methods_in_order(rows)
    ]
    return header + "\n".join(lines) + "\n"


def per_scenario_table(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """The same table for each scenario."""
    parts = []
    for scenario in dict.fromkeys(r["scenario"] for r in rows):
        parts.append(
            f"### {scenario}\n\n" + table(protocol, [r for r in rows if r["scenario"] == scenario])
        )
    return "\n".join(parts)


def figures(protocol: str, rows: Sequence[dict[str, Any]], out: Path) -> list[Path]:
    """Bar charts: IDF1 and event recall per method, false absence; or F1 per scene and method."""
    methods = methods_in_order(rows)
    written = []
    if protocol == "dynamic":
        idf1 = [mean_std([r["idf1"] for r in rows if r["method"] == m])[0] for m in methods]
        recall = [ratio_of(pooled(rows, m, "events_recalled", "events_total")) for m in methods]
        written.append(
            _bars(
                out / "idf1_event_recall.png",
                methods,
                {"IDF1": idf1, "event recall": recall},
                "Identity and event recall",
            )
        )
        absence = [
            ratio_of(pooled(rows, m, "false_absent_checkpoints", "eligible_checkpoints"))
            for m in methods
        ]
        written.append(
            _bars(
                out / "false_absence.png",
                methods,
                {"false absence": absence},
                "False absence (lower is better)",
            )
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
    protocol: str, rows: Sequence[dict[str, Any]], out: Path, seeds: Sequence[int]
) -> list[Path]:
    """results.json, table.md and the figures under `out`."""
    out.mkdir(parents=True, exist_ok=True)
    scenarios = {
        r["scenario"]: {"file": r["scenario_file"], "sha256": r["scenario_sha256"]} for r in rows
    }
    results = {
        "protocol": protocol,
        "code_version": code_version(),
        "seeds": list(seeds),
        "scenarios": scenarios,
        "runs": list(rows),
    }
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    title = (
        "Dynamic memory (the paper's Table 2)"
        if protocol == "dynamic"
        else "Coarse fixtures (the paper's Table 1)"
    )
    text = (
        f"# {title}\n\nMean ± sample std over {len({(r['scenario'], r['seed']) for r in rows})} scenario-seed runs "
        f"(seeds {', '.join(map(str, seeds))}); code {results['code_version']}.\n\n"
        + table(protocol, rows)
        + "\n## Per scenario\n\n"
        + per_scenario_table(protocol, rows)
    )
    (out / "table.md").write_text(text)
    return [out / "results.json", out / "table.md", *figures(protocol, rows, out)]
