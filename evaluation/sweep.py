"""The appearance sensitivity sweep: identity figures against the overlap of appearances.

`python -m evaluation.sweep` runs the dynamic protocol on generated development worlds once per
value of the simulated detector's `appearance.distinctiveness` (the overlap knob of
sim/scenarios/README.md: lower values make two instances of a class look more alike, and one
instance's views less alike), every other setting at its default, and writes one table: IDF1,
identity switches per world and event recall per method and value (the strict readings, the
lenient ones beside), with 95% bootstrap intervals over worlds. Development worlds only: the
sweep is a trace, not a published score.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from core.profiles import EXTENDED
from evaluation.confidence import spelled
from evaluation.methods import DYNAMIC_METHODS, method_named
from evaluation.protocols import run_protocol
from evaluation.report import code_version
from evaluation.world_intervals import intervals
from evaluation.worlds import GENERATED_STREAM_SEED, world_files

DEFAULT_VALUES = (0.25, 0.5, 0.75, 1.0)
DEFAULT_METHODS = (EXTENDED.label, "ConceptGraphs-inspired")
# The strict headlines, each with its lenient reading beside (evaluation.tables.READINGS).
FIGURES = (
    ("idf1", "IDF1"),
    ("id_switches_any_class", "IDS per world"),
    ("id_switches", "IDS class-aware (lenient)"),
    ("event_recall_identity", "Event R."),
    ("event_recall", "Event R. lenient"),
)


def overrides(value: float) -> dict[str, Any]:
    """The scenario fields one point of the sweep sets."""
    return {"detector": {"appearance": {"distinctiveness": value}}}


def sweep_table(points: dict[float, list[dict[str, Any]]]) -> str:
    """One row per (method, value), the figures with their intervals."""
    lines = [
        "| method | distinctiveness | " + " | ".join(title for _, title in FIGURES) + " |",
        "| --- | --- | " + " | ".join("---" for _ in FIGURES) + " |",
    ]
    by_value = {value: intervals("dynamic", rows) for value, rows in points.items()}
    methods = list(dict.fromkeys(m for table in by_value.values() for m in table))
    for method in methods:
        for value, table in by_value.items():
            cells = [spelled(table[method][key]) for key, _ in FIGURES]
            lines.append(f"| {method} | {value:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m evaluation.sweep", description=__doc__)
    parser.add_argument("--generated", type=int, default=6, help="development worlds (6)")
    parser.add_argument("--values", type=float, nargs="+", default=list(DEFAULT_VALUES))
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--frames", type=int, help="shorten every world to N frames")
    parser.add_argument("--jobs", type=int, default=1, help="worlds side by side")
    parser.add_argument("--out", type=Path, default=Path("evaluation/results/dev/sweep"))
    args = parser.parse_args(argv)
    bad = [v for v in args.values if not 0.0 <= v <= 1.0]
    if bad:
        print(f"evaluation.sweep: --values: {bad[0]} is outside [0, 1]", file=sys.stderr)
        return 2
    try:
        methods = [method_named(name, DYNAMIC_METHODS) for name in args.methods]
    except KeyError as error:
        print(f"evaluation.sweep: --methods: {error.args[0]}", file=sys.stderr)
        return 2
    paths = world_files(args.generated, "dev", args.out)
    points: dict[float, list[dict[str, Any]]] = {}
    for value in args.values:
        print(f"evaluation.sweep: distinctiveness {value:g}", file=sys.stderr, flush=True)
        points[value] = run_protocol(
            "dynamic",
            paths,
            [GENERATED_STREAM_SEED],
            methods,
            progress=False,
            frames=args.frames,
            jobs=args.jobs,
            scenario_overrides=overrides(value),
        )
    table = sweep_table(points)
    header = (
        f"Appearance sweep: {args.generated} generated development worlds, stream seed "
        f"{GENERATED_STREAM_SEED}, code {code_version()}; 95% bootstrap intervals over worlds.\n\n"
    )
    (args.out / "table.md").write_text(header + table)
    document = {
        "code_version": code_version(),
        "values": args.values,
        "runs": {str(value): rows for value, rows in points.items()},
    }
    (args.out / "results.json").write_text(json.dumps(document, indent=2) + "\n")
    print(header + table)
    print(f"wrote {args.out / 'table.md'} and {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
