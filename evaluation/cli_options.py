"""The options of `pbdag eval`'s protocols (the command itself is evaluation/cli.py)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_active_options(active: argparse.ArgumentParser) -> None:
    """The options of `eval active`."""
    active.add_argument(
        "--scenario", nargs="+", type=Path, help="active world YAML files (default: the shipped)"
    )
    add_world_options(active)
    active.add_argument(
        "--out",
        type=Path,
        default=Path("evaluation/results") / "active",
        help="folder of results.json, table.md and figures (default: evaluation/results/active)",
    )
    active.add_argument(
        "--orders",
        nargs="+",
        default=["pbdag", "nearest", "fifo", "random"],
        help="acquisition orders (pbdag, nearest, fifo, random; default: all)",
    )
    active.add_argument(
        "--budgets",
        nargs="+",
        type=int,
        default=[2, 4, 6, 8],
        help="inspection budgets of the paired comparison",
    )
    active.add_argument("--keyframes", type=int, default=600, help="coarse-discovery budget")
    active.add_argument("--via-service", metavar="URL", help="run through this service's API")
    active.add_argument("--token", help="bearer token for --via-service (default: $PBDAG_TOKEN)")
    active.add_argument("--params", metavar="JSON", help="overrides of core/params.py")
    active.add_argument(
        "--profile",
        choices=["extended", "paper"],
        default="extended",
        help="the method's parameter set (core/profiles.py), under --params (default: extended)",
    )
    active.add_argument(
        "--keyframe-objects",
        action="store_true",
        help="navigation keyframes also run the object detector (not in the paper's pipeline)",
    )
    active.add_argument(
        "--no-verifier",
        action="store_true",
        help="leave the verification queue and parent verification unanswered",
    )
    active.add_argument(
        "--verifier-error-rate",
        type=float,
        default=0.0,
        help="share of the simulated verifier's answers that are wrong (default: 0)",
    )
    active.add_argument("--quiet", action="store_true", help="no progress lines")


def add_passive_options(parser: argparse.ArgumentParser, protocol: str) -> None:
    """The options of `eval dynamic` and `eval fixtures`."""
    parser.add_argument(
        "--scenario",
        nargs="+",
        type=Path,
        help="scenario YAML files (default: every shipped one)",
    )
    add_world_options(parser)
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("evaluation/results") / protocol,
        help=f"folder of results.json, table.md and figures (default: evaluation/results/{protocol})",
    )
    parser.add_argument(
        "--methods", nargs="+", help="method names (default: all of the protocol's)"
    )
    parser.add_argument(
        "--via-service", metavar="URL", help="run PBD-AG through this service's HTTP API"
    )
    parser.add_argument("--token", help="bearer token for --via-service (default: $PBDAG_TOKEN)")
    parser.add_argument(
        "--frames", type=int, help="shorten every scenario to N frames (same story, faster)"
    )
    parser.add_argument(
        "--params",
        metavar="JSON",
        help="parameter overrides for every method and world, e.g. "
        '\'{"visibility": {"min_expected_image_fraction": 0.001}}\' (each method\'s own '
        "settings still apply on top; default: core/params.py)",
    )
    parser.add_argument(
        "--scenario-overrides",
        metavar="JSON",
        help="fields merged into every world's scenario, e.g. "
        '\'{"detector": {"appearance": {"distinctiveness": 0.3}}}\' (a sensitivity sweep)',
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def add_world_options(parser: argparse.ArgumentParser) -> None:
    """--seeds, --generated N --split dev|test, and --jobs."""
    parser.add_argument(
        "--seeds",
        nargs="+",
        type=int,
        help="seeds per world (default: 7 17 27 on scenario files, 7 on generated worlds)",
    )
    parser.add_argument(
        "--generated",
        type=int,
        metavar="N",
        help="run on the first N generated worlds of --split instead of scenario files "
        "(written to OUT/worlds/)",
    )
    parser.add_argument(
        "--split",
        choices=("dev", "test"),
        default="dev",
        help="which generated worlds: dev (traces and tuning) or test (reporting only); "
        "default: dev",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="worlds run side by side in this many processes (default: 1)",
    )
