"""The ablation tables of `pbdag eval ablation`: what each extension adds, and the gate ablation
read twice, as paired differences over the same worlds with 95% bootstrap intervals.

- Leave one out: for each extension of `core/profiles.py`, the extended profile minus the
  extended profile without it (what the extension adds, everything else on).
- The gate, first reading: the paper's profile minus the same without the visibility gate
  (what the paper's gate does alone).
- The gate, second reading: the paper's profile with one condition of ours added to its gate,
  minus the paper's profile (what each condition adds to the paper's gate).

A difference counts as measurable when its interval excludes 0.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from core.profiles import EXTENSIONS, extension_named
from evaluation.confidence import (
    Interval,
    excludes_zero,
    mean_difference_interval,
    ratio_difference_interval,
    signed,
)
from evaluation.methods import OURS, PAPERS

# The headline figures (strict readings): key, column title, fields, and whether more is better.
EFFECT_FIGURES: tuple[tuple[str, str, tuple[str, ...], bool], ...] = (
    ("idf1", "ΔIDF1", ("idf1",), True),
    ("id_switches_any_class", "ΔIDS per world", ("id_switches_any_class",), False),
    ("event_recall_identity", "ΔEvent R.", ("events_recalled_identity", "events_total"), True),
    (
        "false_absence_identity",
        "ΔFalse abs.",
        ("false_absent_checkpoints_identity", "eligible_checkpoints_identity"),
        False,
    ),
)


def comparisons() -> list[tuple[str, str, str, str]]:
    """(row, what it isolates, the method with it, the method without it), in table order."""
    rows = [(e.name, f"{e.title} (for {e.case})", OURS, f"{OURS} - {e.name}") for e in EXTENSIONS]
    rows.append(
        (
            "paper's gate vs none",
            "the paper's visibility gate alone",
            PAPERS,
            f"{PAPERS} w/o visibility gate",
        )
    )
    rows += [
        (
            f"paper's gate + {name}",
            f"{extension_named(name).title}, added to the paper's gate",
            f"{PAPERS} + {name}",
            PAPERS,
        )
        for name in ("empty_place", "missed_detection")
    ]
    return rows


def _paired(
    rows: Sequence[Mapping[str, Any]], with_it: str, without: str
) -> list[tuple[Mapping[str, Any], Mapping[str, Any]]]:
    """The two methods' runs on the same (world, seed), in a fixed order."""
    by_run = {(r["scenario"], r["seed"], r["method"]): r for r in rows if "error" not in r}
    keys = sorted({(r["scenario"], r["seed"]) for r in rows})
    return [
        (by_run[(*key, with_it)], by_run[(*key, without)])
        for key in keys
        if (*key, with_it) in by_run and (*key, without) in by_run
    ]


def effect(
    rows: Sequence[Mapping[str, Any]], with_it: str, without: str
) -> dict[str, Interval] | None:
    """Per headline figure: (with) - (without) over their paired runs; None without pairs."""
    pairs = _paired(rows, with_it, without)
    if not pairs:
        return None
    figures: dict[str, Interval] = {}
    for key, _, fields, _ in EFFECT_FIGURES:
        if len(fields) == 2:
            figures[key] = ratio_difference_interval(
                ([a[fields[0]] for a, _ in pairs], [a[fields[1]] for a, _ in pairs]),
                ([b[fields[0]] for _, b in pairs], [b[fields[1]] for _, b in pairs]),
            )
        else:
            figures[key] = mean_difference_interval(
                [a[fields[0]] for a, _ in pairs], [b[fields[0]] for _, b in pairs]
            )
    return figures


def verdict(figures: Mapping[str, Interval]) -> str:
    """Which headline figures the difference measurably improves or worsens."""
    better: list[str] = []
    worse: list[str] = []
    for key, title, _, more_is_better in EFFECT_FIGURES:
        interval = figures[key]
        if not excludes_zero(interval):
            continue
        improves = (interval.value > 0) == more_is_better
        (better if improves else worse).append(title.removeprefix("Δ"))
    if not better and not worse:
        return "none measurable"
    parts = [f"better {', '.join(better)}"] if better else []
    parts += [f"worse {', '.join(worse)}"] if worse else []
    return "; ".join(parts)


def effects_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown: one row per comparison, each difference with its interval, and the verdict."""
    titles = [title for _, title, _, _ in EFFECT_FIGURES]
    lines = [
        "| Compared | What it isolates | " + " | ".join(titles) + " | Measurable |",
        "|---|---|" + "---|" * len(titles) + "---|",
    ]
    missing = []
    for name, what, with_it, without in comparisons():
        figures = effect(rows, with_it, without)
        if figures is None:
            missing.append(name)
            continue
        cells = [signed(figures[key]) for key, _, _, _ in EFFECT_FIGURES]
        lines.append(f"| {name} | {what} | " + " | ".join(cells) + f" | {verdict(figures)} |")
    worlds = len({(r["scenario"], r["seed"]) for r in rows})
    lines += [
        "",
        f"Paired differences (with - without) over {worlds} world-seed runs, 95% bootstrap "
        "intervals over them in brackets; measurable: the interval excludes 0. Strict readings: "
        "IDS class-agnostic, event recall with the identity kept, false absence "
        "identity-conditioned.",
    ]
    if missing:
        lines.append("Not in these runs: " + ", ".join(missing) + ".")
    return "\n".join(lines) + "\n"


def effects_json(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """What results.json keeps of the effects."""
    document: dict[str, Any] = {}
    for name, _, with_it, without in comparisons():
        figures = effect(rows, with_it, without)
        if figures is not None:
            document[name] = {
                "with": with_it,
                "without": without,
                **{key: interval.as_json() for key, interval in figures.items()},
                "verdict": verdict(figures),
            }
    return document


def write_effects(rows: Sequence[Mapping[str, Any]], out: Path) -> str:
    """Add the effects to a run's results.json (`effects`) and table.md; the table."""
    text = effects_table(rows)
    results = out / "results.json"
    document = json.loads(results.read_text())
    document["effects"] = effects_json(rows)
    results.write_text(json.dumps(document, indent=2) + "\n")
    page = out / "table.md"
    page.write_text(page.read_text() + "\n## What each extension adds\n\n" + text)
    return text


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m evaluation.ablation OUT`: write the effects of an ablation run already in OUT
    (its results.json rows) into its results.json and table.md."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m evaluation.ablation", description=__doc__)
    parser.add_argument("out", type=Path, help="the folder of an `pbdag eval ablation` run")
    args = parser.parse_args(argv)
    results = args.out / "results.json"
    if not results.is_file():
        print(f"evaluation.ablation: {results}: no such file", file=sys.stderr)
        return 2
    document = json.loads(results.read_text())
    if "## What each extension adds" in (args.out / "table.md").read_text():
        print(f"evaluation.ablation: {args.out}/table.md has the effects already", file=sys.stderr)
        return 2
    print(write_effects(document["runs"], args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
