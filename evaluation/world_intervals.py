"""The tables of a run over many worlds: every figure with its bootstrap interval over worlds."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from evaluation.confidence import Interval, mean_interval, ratio_interval, spelled
from evaluation.tables import methods_in_order, ran, readings_note

# (key, title, kind): a mean over worlds, or a pooled ratio of two per-world counts. Each strict
# headline (evaluation.tables.READINGS) comes first, its lenient reading beside it.
DYNAMIC_FIGURES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("idf1", "IDF1↑", ("idf1",)),
    ("id_presence_f1", "ID-Pres.↑", ("id_presence_f1",)),
    ("id_switches_any_class", "IDS↓ (per world)", ("id_switches_any_class",)),
    ("id_switches", "IDS class-aware (lenient)↓", ("id_switches",)),
    ("event_recall_identity", "Event R.↑", ("events_recalled_identity", "events_total")),
    ("event_recall", "Event R. lenient↑", ("events_recalled", "events_total")),
    ("carry_recall", "Moves+transfers R.↑", ("carries_recalled_identity", "carries_total")),
    (
        "removal_recall_seen_empty",
        "Removals R. (place seen empty ≥3)↑",
        ("removals_seen_empty_recalled", "removals_seen_empty"),
    ),
    (
        "false_absence_identity",
        "False abs.↓",
        ("false_absent_checkpoints_identity", "eligible_checkpoints_identity"),
    ),
    (
        "false_absence",
        "False abs. identity-agnostic (lenient)↓",
        ("false_absent_checkpoints", "eligible_checkpoints"),
    ),
)
FIXTURE_FIGURES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("precision", "P↑", ("precision",)),
    ("recall", "R↑", ("recall",)),
    ("f1", "F1↑", ("f1",)),
    ("center_error", "Err. [m]↓", ("center_error",)),
    ("count_mae", "MAE↓", ("count_mae",)),
)


def _figures(protocol: str) -> tuple[tuple[str, str, tuple[str, ...]], ...]:
    return DYNAMIC_FIGURES if protocol == "dynamic" else FIXTURE_FIGURES


def missing_fields(protocol: str, rows: Sequence[dict[str, Any]]) -> list[str]:
    """The fields a figure reads that some run lacks (a results.json written before the figure
    existed): its cells show "-" rather than a figure over part of the runs."""
    needed = dict.fromkeys(field for _, _, fields in _figures(protocol) for field in fields)
    return [field for field in needed if any(field not in row for row in ran(rows))]


def intervals(protocol: str, rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Interval]]:
    """Per method, per figure: the value over every world and its 95% bootstrap interval (a
    figure some run lacks a field of is left out: `missing_fields`)."""
    rows = ran(rows)
    table: dict[str, dict[str, Interval]] = {}
    for method in methods_in_order(rows):
        mine = [r for r in rows if r["method"] == method]
        figures: dict[str, Interval] = {}
        for key, _, fields in _figures(protocol):
            if any(field not in row for row in mine for field in fields):
                continue
            if len(fields) == 2:
                figures[key] = ratio_interval(
                    [r[fields[0]] for r in mine], [r[fields[1]] for r in mine]
                )
                continue
            values = [r[fields[0]] for r in mine if r[fields[0]] is not None]
            if values:
                figures[key] = mean_interval(values)
        table[method] = figures
    return table


def intervals_json(protocol: str, rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """What results.json keeps of `intervals`."""
    return {
        method: {key: interval.as_json() for key, interval in figures.items()}
        for method, figures in intervals(protocol, rows).items()
    }


def over(rows: Sequence[Mapping[str, Any]]) -> str:
    """What the intervals resample: `Over 30 worlds`, or `Over 15 runs (5 worlds x seeds)`."""
    runs = len({(r["scenario"], r["seed"]) for r in rows})
    worlds = len({r["scenario"] for r in rows})
    return (
        f"Over {runs} worlds" if runs == worlds else f"Over {runs} runs ({worlds} worlds x seeds)"
    )


def interval_table(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: one row per method, each cell `value [low, high]`."""
    table = intervals(protocol, rows)
    figures = _figures(protocol)
    lines = [
        f"{over(ran(rows))}; 95% bootstrap intervals over them in brackets.",
        "",
        "| Method | " + " | ".join(title for _, title, _ in figures) + " |",
        "|---|" + "---|" * len(figures),
    ]
    for method, values in table.items():
        cells = [spelled(values[key]) if key in values else "-" for key, _, _ in figures]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    missing = missing_fields(protocol, rows)
    if missing:
        lines += [
            "",
            "Not in these runs' results.json (written before the figure existed), so shown as "
            "-: " + ", ".join(f"`{field}`" for field in missing) + ".",
        ]
    if protocol == "dynamic":
        lines += ["", readings_note().rstrip("\n")]
    return "\n".join(lines) + "\n"
