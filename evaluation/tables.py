"""The markdown of a report: the paper's tables, the latency distribution and the shortfalls.

Dynamic rows are pooled where the paper pools (event recall over scheduled events, false absence
over eligible checkpoints) and averaged elsewhere (mean ± sample std over scenario-seed runs).
IDS, Event R. and False abs. are read strictly wherever a headline shows them (`READINGS`); the
lenient reading of each is printed beside it, its column marked lenient.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from core.profiles import EXTENDED
from evaluation.change_metrics import latency_summary
from evaluation.metrics import mean_std

PAPER_SCENARIO = "hotel-suite"  # the paper's Table 2 is the hotel suite alone
SUBJECT = EXTENDED.label  # the method whose shortfalls the report spells out
DYNAMIC_COLUMNS = (
    ("idf1", "IDF1↑"),
    ("id_presence_f1", "ID-Pres.↑"),
    ("id_switches_any_class", "IDS↓"),
    ("id_switches", "IDS class-aware (lenient)↓"),
)


@dataclass(frozen=True)
class Reading:
    """A figure's two readings: the strict one every headline shows, the lenient one beside it
    (each named by the key of a run's row that holds it)."""

    figure: str
    strict: str
    lenient: str
    strict_means: str
    lenient_means: str

    def as_json(self) -> dict[str, str]:
        """What results.json says of it."""
        return {
            "headline": self.strict,
            "headline_reads": self.strict_means,
            "lenient": self.lenient,
            "lenient_reads": self.lenient_means,
        }


READINGS = (
    Reading(
        "IDS",
        "id_switches_any_class",
        "id_switches",
        "class-agnostic: a track passing from one object to another is a switch whatever the "
        "labels",
        "class-aware: a node matches only an object of its label",
    ),
    Reading(
        "Event R.",
        "events_recalled_identity",
        "events_recalled",
        "a move or transfer counts only when the identity the object had before it is the one "
        "at its new place; a new track there is not the event",
        "any recalling event of the object's assigned track over the run, a new track's first "
        "parent included",
    ),
    Reading(
        "False abs.",
        "false_absence_identity",
        "false_absence",
        "identity-conditioned: the object's assigned track is not published",
        "identity-agnostic: no published node of the object's class within 0.5 m of it",
    ),
)


def readings_note() -> str:
    """Under a dynamic table: what each strict headline reads, and its lenient column beside."""
    lines = ["Headlines read strictly; the columns marked lenient are printed for comparison:"]
    lines += [
        f"- {r.figure}: {r.strict_means} (`{r.strict}`). Lenient: {r.lenient_means} "
        f"(`{r.lenient}`)."
        for r in READINGS
    ]
    return "\n".join(lines) + "\n"


FIXTURE_COLUMNS = (
    ("precision", "P↑"),
    ("recall", "R↑"),
    ("f1", "F1↑"),
    ("center_error", "Err. [m]↓"),
    ("count_mae", "MAE↓"),
)


def short(value: float) -> str:
    """The paper's number format: .833 rather than 0.833."""
    text = f"{value:.3f}"
    return text[1:] if text.startswith("0.") else text


def cell(values: Sequence[float | None]) -> str:
    """mean ± sample std, the paper's format (.833±.029)."""
    numbers = [v for v in values if v is not None]
    if not numbers:
        return "-"
    mean, std = mean_std(numbers)
    return f"{short(mean)}±{short(std)}"


def ran(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows of methods that ran (not the ones this core cannot run yet)."""
    return [row for row in rows if "unavailable" not in row]


def methods_in_order(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Methods in the order they ran."""
    return list(dict.fromkeys(row["method"] for row in rows))


def pooled(
    rows: Sequence[dict[str, Any]], method: str, numerator: str, denominator: str
) -> tuple[int, int]:
    """A method's counts summed over its runs."""
    mine = [r for r in rows if r["method"] == method]
    return sum(r[numerator] for r in mine), sum(r[denominator] for r in mine)


def ratio_of(counts: tuple[int, int]) -> float:
    """numerator / denominator, 0 when there is nothing to count."""
    return counts[0] / counts[1] if counts[1] else 0.0


def latencies(rows: Sequence[dict[str, Any]], method: str) -> tuple[list[int], int]:
    """A method's event latencies in batches (events reflected in the strict reading) and how
    many it never reflected."""
    values, missed = [], 0
    for row in rows:
        if row["method"] != method:
            continue
        for entry in row["event_trace"]:
            if entry["latency_batches_identity"] is None:
                missed += 1
            else:
                values.append(entry["latency_batches_identity"])
    return sorted(values), missed


def _bound(rows: Sequence[dict[str, Any]]) -> str:
    bounds = sorted({row["event_latency_bound_batches"] for row in rows})
    return "/".join(str(bound) for bound in bounds) or "-"


def dynamic_table(rows: Sequence[dict[str, Any]]) -> str:
    """Table 2's columns, each strict headline with its lenient reading beside, and the latency."""
    rows = ran(rows)
    header = (
        "| Method | "
        + " | ".join(title for _, title in DYNAMIC_COLUMNS)
        + f" | Event R.↑ (≤{_bound(rows)} b) | Event R. lenient↑ | False abs.↓ "
        "| False abs. identity-agnostic (lenient)↓ | Latency med/max [b] |\n|---|"
        + "---|" * (len(DYNAMIC_COLUMNS) + 5)
        + "\n"
    )
    lines = []
    for method in methods_in_order(rows):
        mine = [r for r in rows if r["method"] == method]
        recalled, total = pooled(rows, method, "events_recalled_identity", "events_total")
        lenient, _ = pooled(rows, method, "events_recalled", "events_total")
        by_identity = ratio_of(
            pooled(
                rows, method, "false_absent_checkpoints_identity", "eligible_checkpoints_identity"
            )
        )
        agnostic = ratio_of(
            pooled(rows, method, "false_absent_checkpoints", "eligible_checkpoints")
        )
        summary = latency_summary(latencies(rows, method)[0])
        latency = "-" if summary is None else f"{summary[0]:g}/{summary[1]}"
        cells = [cell([r.get(key) for r in mine]) for key, _ in DYNAMIC_COLUMNS]
        lines.append(
            f"| {method} | {' | '.join(cells)} | {recalled}/{total} | {lenient}/{total} "
            f"| {short(by_identity)} | {short(agnostic)} | {latency} |"
        )
    return header + "\n".join(lines) + "\n"


def fixture_table(rows: Sequence[dict[str, Any]]) -> str:
    """Table 1's columns."""
    rows = ran(rows)
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


def table(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """The protocol's table over the given rows."""
    return dynamic_table(rows) if protocol == "dynamic" else fixture_table(rows)


def per_scenario_tables(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """The same table for each scenario."""
    return "\n".join(
        f"### {scenario}\n\n" + table(protocol, [r for r in rows if r["scenario"] == scenario])
        for scenario in dict.fromkeys(r["scenario"] for r in rows)
    )


def latency_section(rows: Sequence[dict[str, Any]]) -> str:
    """Per method, the latency in batches of every event the strict reading counts (pooled over
    runs), and the events it never reflected."""
    rows = ran(rows)
    lines = [
        "| Method | latencies of reflected events [batches] | never reflected |",
        "|---|---|---|",
    ]
    for method in methods_in_order(rows):
        values, missed = latencies(rows, method)
        counts = Counter(values)
        spelled = ", ".join(
            f"{value} (x{count})" if count > 1 else str(value)
            for value, count in sorted(counts.items())
        )
        lines.append(f"| {method} | {spelled or '-'} | {missed} |")
    return "\n".join(lines) + "\n"


def _missed_event(row: dict[str, Any], entry: dict[str, Any]) -> str:
    """One change the strict reading did not count within the bound, with its trace."""
    seen = entry["observable_frame"]
    latency = entry["latency_batches_identity"]
    before = entry["identity_before"]
    lenient = (
        "the lenient reading counts it"
        if entry["recalled"]
        else "the lenient reading does not count it either"
    )
    return (
        f"- {row['scenario']} seed {row['seed']}: {entry['type']} of {entry['object']} at "
        f"frame {entry['frame']} (observable from "
        f"{'never' if seen is None else f'frame {seen}'}), track {entry['track'] or 'none'}, "
        f"identity before it {before or 'none'}, "
        + ("never reflected" if latency is None else f"reflected after {latency} batches")
        + f" ({lenient}); track from then on: {' '.join(entry['track_story']) or '-'}"
    )


def shortfalls(rows: Sequence[dict[str, Any]], method: str = SUBJECT, worst: int = 3) -> str:
    """The subject's events missed or late in the strict reading, with their traces, and its
    most false-absent objects (identity-conditioned)."""
    mine = [r for r in ran(rows) if r["method"] == method]
    lines = [
        _missed_event(row, entry)
        for row in mine
        for entry in row["event_trace"]
        if not entry["recalled_identity"]
    ]
    absent: Counter[tuple[str, int, str]] = Counter()
    for row in mine:
        for object_id, count in row["false_absence_identity_by_object"].items():
            absent[row["scenario"], row["seed"], object_id] += count
    for (scenario, seed, object_id), count in absent.most_common(worst):
        lines.append(
            f"- {scenario} seed {seed}: {object_id} was present, acquired, and its {method} "
            f"track not published at {count} checkpoints"
        )
    if not lines:
        return f"{method} missed no event and had no false absence.\n"
    return "\n".join(lines) + "\n"


def unavailable_note(rows: Sequence[dict[str, Any]]) -> str:
    """Methods this core could not run, with the reason (empty when all ran)."""
    reasons = {row["method"]: row["unavailable"] for row in rows if "unavailable" in row}
    return "".join(f"- {method}: not run ({reason}).\n" for method, reason in reasons.items())


def console_summary(protocol: str, rows: Sequence[dict[str, Any]]) -> str:
    """What `pbdag eval` prints: the headline and pooled tables (the rest is in table.md)."""
    if protocol != "dynamic":
        return table(protocol, rows)
    paper_rows = [r for r in rows if r["scenario"] == PAPER_SCENARIO]
    text = f"{PAPER_SCENARIO} alone (the paper's Table 2):\n" + table(protocol, paper_rows) + "\n"
    if not paper_rows:
        text = ""
    return text + "Pooled over every scenario:\n" + table(protocol, rows) + unavailable_note(rows)
