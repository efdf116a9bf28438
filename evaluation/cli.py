"""`pbdag eval dynamic|fixtures`: the paper's protocols on shipped or custom scenario files."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim import SCENARIOS_DIR

SHIPPED = [
    "hotel-suite.yaml",
    "bedroom.yaml",
    "office.yaml",
    "kitchen-real.yaml",
    "busy-living-room.yaml",
]
DEFAULT_SCENARIOS = {"dynamic": SHIPPED, "fixtures": SHIPPED}


def register(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add `eval` to the `pbdag` command (loaded through the pbdag.commands entry point)."""
    evaluate = commands.add_parser(
        "eval", help="run the paper's evaluation protocols on simulated worlds"
    )
    protocols = evaluate.add_subparsers(dest="protocol", required=True)
    for protocol, help_text in (
        (
            "dynamic",
            "dynamic memory: IDF1, identity switches, event recall, false absence (Table 2)",
        ),
        (
            "fixtures",
            "coarse fixtures under shared evidence: precision, recall, F1, center error, count MAE (Table 1)",
        ),
    ):
        parser = protocols.add_parser(protocol, help=help_text)
        parser.add_argument(
            "--scenario",
            nargs="+",
            type=Path,
            help="scenario YAML files (default: every shipped one)",
        )
        parser.add_argument("--seeds", nargs="+", type=int, default=[7, 17, 27])
        parser.add_argument("--out", type=Path, default=Path("evaluation/results") / protocol)
        parser.add_argument(
            "--methods", nargs="+", help="method names (default: all of the protocol's)"
        )
        parser.add_argument(
            "--via-service", metavar="URL", help="run PBD-AG through this service's HTTP API"
        )
        parser.add_argument(
            "--token", help="bearer token for --via-service (default: $PBDAG_TOKEN)"
        )
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
        parser.add_argument("--quiet", action="store_true", help="no progress bar")
        parser.set_defaults(handler=run)


def loadable(given: list[Path] | None, defaults: list[str]) -> list[Path] | None:
    """The scenario files to run. A shipped one that cannot load here (the real sequence it
    reads is not beside this clone) is left out with a note; a given one that cannot load is
    an error (None)."""
    from sim.scenario import ScenarioError, load_scenario

    paths = given or [SCENARIOS_DIR / name for name in defaults]
    kept = []
    for path in paths:
        try:
            load_scenario(path)
        except (ScenarioError, OSError) as error:
            if given:
                print(f"pbdag eval: {path}: {error}", file=sys.stderr)
                return None
            print(f"pbdag eval: leaving out {path.name}: {error}", file=sys.stderr)
            continue
        kept.append(path)
    return kept


def run(args: argparse.Namespace) -> int:
    """Run a protocol and write its report."""
    # Imported here so that `pbdag serve` never loads the simulator (open3d) just to build its CLI.
    import json
    import os

    import httpx

    from core.errors import InvalidParams
    from core.params import Params
    from evaluation.methods import DYNAMIC_METHODS, FIXTURE_METHODS, method_named, with_params
    from evaluation.protocols import run_protocol
    from evaluation.report import write_report
    from evaluation.tables import console_summary

    protocol = args.protocol
    scenarios = loadable(args.scenario, DEFAULT_SCENARIOS[protocol])
    if scenarios is None:
        return 2
    catalogue = DYNAMIC_METHODS if protocol == "dynamic" else FIXTURE_METHODS
    methods = (
        [method_named(name, catalogue) for name in args.methods]
        if args.methods
        else list(catalogue)
    )
    overrides: dict[str, object] = {}
    if args.params:
        try:
            overrides = json.loads(args.params)
            if not isinstance(overrides, dict):
                raise ValueError("expected a JSON object")
            Params.from_dict(overrides)
        except (ValueError, InvalidParams) as error:
            print(f"pbdag eval: --params: {error}", file=sys.stderr)
            return 2
        methods = with_params(methods, overrides)
    token = args.token or os.environ.get("PBDAG_TOKEN")
    client = (
        httpx.Client(
            base_url=args.via_service.rstrip("/"),
            timeout=60.0,
            headers={"Authorization": f"Bearer {token}"} if token else {},
        )
        if args.via_service
        else None
    )
    try:
        rows = run_protocol(
            protocol,
            scenarios,
            args.seeds,
            methods,
            via_service=client,
            progress=not args.quiet,
            frames=args.frames,
        )
    finally:
        if client is not None:
            client.close()
    written = write_report(protocol, rows, args.out, args.seeds, overrides)
    print(console_summary(protocol, rows))
    for path in written:
        print(f"wrote {path}")
    return 0
