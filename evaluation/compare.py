"""Two runs of one method on the same worlds, side by side: each figure of the dynamic interval
table (or, for two runs of `pbdag eval active`, coarse F1 and fine P/R/F1 of one acquisition
order) with its interval, and their paired difference with its interval (the worlds resampled
once for both). What `python -m evaluation.compare BEFORE AFTER` prints, for a change to the
method measured against the code before it.

    python -m evaluation.compare before/results.json after/results.json [--method NAME] [--out F]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from evaluation.confidence import (
    Interval,
    excludes_zero,
    mean_difference_interval,
    mean_interval,
    ratio_difference_interval,
    ratio_interval,
    signed,
    spelled,
)
from evaluation.methods import OURS
from evaluation.world_intervals import DYNAMIC_FIGURES

Row = Mapping[str, Any]
Figures = Sequence[tuple[str, str, tuple[str, ...]]]
# An active run's figures: Table 3's F1s and the fine P/R, read from its `coarse` and `fine`.
ACTIVE_FIGURES: Figures = (
    ("coarse_f1", "coarse F1↑", ("coarse_f1",)),
    ("fine_precision", "fine P↑", ("fine_precision",)),
    ("fine_recall", "fine R↑", ("fine_recall",)),
    ("fine_f1", "fine F1↑", ("fine_f1",)),
)
ACTIVE_DEFAULT = "pbdag"  # the order compared in an active run unless --method names another


def active_rows(runs: Sequence[Row]) -> list[dict[str, Any]]:
    """An active results.json's rollouts in the shape `paired_runs` reads: the acquisition
    order is the method, and Table 3's figures are flat fields."""
    return [
        {
            "scenario": r["scenario"],
            "seed": r["seed"],
            "method": r["order"],
            "coarse_f1": r["coarse"]["f1"],
            **{f"fine_{key}": r["fine"][key] for key in ("precision", "recall", "f1")},
        }
        for r in runs
    ]


def paired_runs(before: Sequence[Row], after: Sequence[Row], method: str) -> list[tuple[Row, Row]]:
    """The method's runs in both, on the same (world, seed), in a fixed order."""

    def keyed(rows: Sequence[Row]) -> dict[tuple[str, int], Row]:
        return {
            (r["scenario"], r["seed"]): r
            for r in rows
            if r["method"] == method and "error" not in r
        }

    first, second = keyed(before), keyed(after)
    return [(first[key], second[key]) for key in sorted(first.keys() & second.keys())]


def compared(
    pairs: Sequence[tuple[Row, Row]], figures: Figures = DYNAMIC_FIGURES
) -> list[tuple[str, Interval, Interval, Interval]]:
    """(figure, before, after, after - before) for every figure both runs hold."""
    table = []
    for _, title, fields in figures:
        if any(field not in row for pair in pairs for row in pair for field in fields):
            continue
        sides = [[pair[side] for pair in pairs] for side in (0, 1)]
        if len(fields) == 2:
            counts = [
                ([r[fields[0]] for r in rows], [r[fields[1]] for r in rows]) for rows in sides
            ]
            values = [ratio_interval(*c) for c in counts]
            difference = ratio_difference_interval(counts[1], counts[0])
        else:
            numbers = [[float(r[fields[0]]) for r in rows] for rows in sides]
            values = [mean_interval(n) for n in numbers]
            difference = mean_difference_interval(numbers[1], numbers[0])
        table.append((title, values[0], values[1], difference))
    return table


def markdown(table: Sequence[tuple[str, Interval, Interval, Interval]], worlds: int) -> str:
    """The comparison as a markdown table; a difference whose interval excludes 0 is marked."""
    lines = [
        f"Over {worlds} paired worlds; 95% bootstrap intervals in brackets; "
        "* marks a difference whose interval excludes 0.",
        "",
        "| figure | before | after | after - before |",
        "| --- | --- | --- | --- |",
    ]
    for title, before, after, difference in table:
        mark = " *" if excludes_zero(difference) else ""
        lines.append(
            f"| {title} | {spelled(before)} | {spelled(after)} | {signed(difference)}{mark} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    """Print (and with --out write) the comparison of two results.json."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("before", type=Path, help="results.json of the code before the change")
    parser.add_argument("after", type=Path, help="results.json of the code after it")
    parser.add_argument(
        "--method",
        default=None,
        help=f"the method compared (default: {OURS}; of active runs, the order {ACTIVE_DEFAULT})",
    )
    parser.add_argument("--out", type=Path, default=None, help="also write the table here")
    args = parser.parse_args(argv)
    runs, protocols = [], set()
    for path in (args.before, args.after):
        try:
            results = json.loads(path.read_text(encoding="utf-8"))
            protocol = results.get("protocol")
            runs.append(active_rows(results["runs"]) if protocol == "active" else results["runs"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
            reason = f"no {error} key" if isinstance(error, KeyError) else str(error)
            message = f"compare: {path}: not a results.json of `pbdag eval` ({reason})"
            raise SystemExit(message) from None
        protocols.add("active" if protocol == "active" else "dynamic")
    if len(protocols) > 1:
        raise SystemExit("compare: one file is of `pbdag eval active`, the other is not")
    active = protocols == {"active"}
    method = args.method or (ACTIVE_DEFAULT if active else OURS)
    pairs = paired_runs(runs[0], runs[1], method)
    if not pairs:
        raise SystemExit(f"no run of {method!r} on the same world and seed in both files")
    text = markdown(compared(pairs, ACTIVE_FIGURES if active else DYNAMIC_FIGURES), len(pairs))
    print(text, end="")
    if args.out is not None:
        args.out.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
