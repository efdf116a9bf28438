"""`pbdag eval dynamic|fixtures|active`: the paper's protocols on shipped or custom scenario files."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from evaluation.cli_options import add_active_options, add_passive_options
from sim import SCENARIOS_DIR

if TYPE_CHECKING:
    from pbdag_client import Client

SHIPPED = [
    "hotel-suite.yaml",
    "bedroom.yaml",
    "office.yaml",
    "kitchen-real.yaml",
    "busy-living-room.yaml",
]
DEFAULT_SCENARIOS = {"dynamic": SHIPPED, "fixtures": SHIPPED, "ablation": SHIPPED}
ACTIVE_SHIPPED = ["active/flat.yaml", "active/suite.yaml", "active/floor.yaml"]
# The `eval` extra of pyproject.toml: the module each of its distributions installs.
EVAL_EXTRA = {
    "open3d": "open3d-cpu",
    "pycocotools": "pycocotools",
    "yaml": "pyyaml",
    "tqdm": "tqdm",
    "motmetrics": "motmetrics",
    "pandas": "pandas",
    "matplotlib": "matplotlib",
}


def missing_eval_distributions() -> list[str]:
    """The distributions of the `eval` extra that are not installed."""
    return [name for module, name in EVAL_EXTRA.items() if importlib.util.find_spec(module) is None]


def needs_eval_extra(
    handler: Callable[[argparse.Namespace], int],
) -> Callable[[argparse.Namespace], int]:
    """The handler, run only when the `eval` extra is installed; else one line saying so."""

    def checked(args: argparse.Namespace) -> int:
        missing = missing_eval_distributions()
        if missing:
            print(
                f"pbdag eval: needs the eval extra (missing {', '.join(missing)}): "
                "install pbdag[eval] (in a clone: pip install -e '.[eval]')",
                file=sys.stderr,
            )
            return 2
        return handler(args)

    return checked


def register(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add `eval` to the `pbdag` command (loaded through the pbdag.commands entry point)."""
    evaluate = commands.add_parser(
        "eval", help="run the paper's evaluation protocols on simulated worlds"
    )
    protocols = evaluate.add_subparsers(
        dest="protocol", required=True, metavar="PROTOCOL", help="the protocol to run"
    )
    for protocol, help_text in (
        (
            "dynamic",
            "dynamic memory: IDF1, identity switches, event recall, false absence (Table 2)",
        ),
        (
            "fixtures",
            "coarse fixtures under shared evidence: precision, recall, F1, center error, count MAE (Table 1)",
        ),
        (
            "ablation",
            "the dynamic protocol over the leave-one-out of every extension (core/profiles.py) "
            "and the two readings of the visibility-gate ablation",
        ),
    ):
        passive = protocols.add_parser(protocol, help=help_text)
        add_passive_options(passive, protocol)
        passive.set_defaults(handler=needs_eval_extra(run))
    active = protocols.add_parser(
        "active",
        help="autonomous construction from an empty map: coarse and fine P/R/F1 (Table 3), "
        "and the paired acquisition orders under inspection budgets",
    )
    add_active_options(active)
    active.set_defaults(handler=needs_eval_extra(run_active))


def world_paths(args: argparse.Namespace, shipped: list[str]) -> list[Path] | None:
    """The scenario files of a run: generated ones, given ones, or the shipped ones (None after
    printing why when they cannot be had). Sets args.seeds to the default when none was given."""
    from evaluation.worlds import GENERATED_STREAM_SEED, world_files

    if args.jobs < 1:
        print(f"pbdag eval: --jobs: {args.jobs} is not a positive number", file=sys.stderr)
        return None
    if args.generated is None:
        args.seeds = args.seeds or [7, 17, 27]
        return loadable(args.scenario, shipped)
    if args.scenario:
        print("pbdag eval: --generated and --scenario exclude each other", file=sys.stderr)
        return None
    if args.generated < 1:
        print(
            f"pbdag eval: --generated: {args.generated} is not a positive number", file=sys.stderr
        )
        return None
    args.seeds = args.seeds or [GENERATED_STREAM_SEED]
    return world_files(args.generated, args.split, args.out, active=args.protocol == "active")


def world_note(args: argparse.Namespace) -> dict[str, Any] | None:
    """What results.json records of generated worlds (None for scenario files)."""
    if args.generated is None:
        return None
    from sim.generator import split_seeds

    return {
        "split": args.split,
        "count": args.generated,
        "world_seeds": list(split_seeds(args.split, args.generated)),
    }


def scenario_changes(text: str | None, scenarios: list[Path]) -> dict[str, Any]:
    """--scenario-overrides as a mapping, checked against every world before anything runs."""
    from sim.scenario import ScenarioError, load_scenario

    if not text:
        return {}
    try:
        changes = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"not JSON: {error}") from error
    if not isinstance(changes, dict):
        raise ValueError("must be a JSON object of scenario fields")
    for path in scenarios:
        try:
            load_scenario(path, changes)
        except ScenarioError as error:
            raise ValueError(f"{path.name}: {error}") from error
    return changes


def parsed_params(text: str | None) -> dict[str, Any]:
    """`--params`: a JSON object of overrides of core/params.py, validated (ValueError naming
    the field otherwise); none given: {}."""
    from core.errors import InvalidParams
    from core.params import Params

    if not text:
        return {}
    overrides = json.loads(text)  # JSONDecodeError is a ValueError
    if not isinstance(overrides, dict):
        raise ValueError("expected a JSON object")
    try:
        Params.from_dict(overrides)
    except InvalidParams as error:
        raise ValueError(str(error)) from error
    return overrides


def service_client(url: str | None, token: str | None) -> Client | None:
    """The service's client for `--via-service` (token: the flag, else $PBDAG_TOKEN)."""
    from pbdag_client import Client

    if not url:
        return None
    return Client(url, token or os.environ.get("PBDAG_TOKEN"), timeout=60.0)


def run_active(args: argparse.Namespace) -> int:
    """Run the active protocol and write its report."""

    import httpx

    from core.params import deep_merge
    from core.profiles import PROFILES
    from evaluation.active import ORDERS, run_rows
    from evaluation.active_report import write
    from evaluation.report import code_version
    from pbdag_client import PbdagError
    from sim.rollout import RolloutSettings
    from sim.scenario import ScenarioError

    def fail(message: str) -> int:
        print(f"pbdag eval active: {message}", file=sys.stderr)
        return 2

    unknown = [o for o in args.orders if o not in ORDERS]
    if unknown:
        return fail(f"--orders: unknown {', '.join(unknown)} (known: {', '.join(ORDERS)})")
    if any(b < 1 for b in args.budgets):
        return fail("--budgets: every budget must be at least 1 inspection")
    if args.keyframes < 1:
        return fail("--keyframes: must be at least 1")
    if not 0.0 <= args.verifier_error_rate <= 1.0:
        return fail("--verifier-error-rate: must lie in [0, 1]")
    if args.generated is None and args.scenario:
        for path in args.scenario:
            if not Path(path).is_file():
                return fail(f"--scenario: {path} is not a file")
    scenarios = world_paths(args, ACTIVE_SHIPPED)
    if scenarios is None:
        return 2
    if args.via_service and args.jobs > 1:
        return fail("--jobs: runs through --via-service go one at a time")
    try:
        overrides = deep_merge(dict(PROFILES[args.profile].overrides), parsed_params(args.params))
    except ValueError as error:
        return fail(f"--params: {error}")
    client = service_client(args.via_service, args.token)
    work = [
        (Path(p), seed, order) for p in scenarios for seed in args.seeds for order in args.orders
    ]
    try:
        runs = run_rows(
            work,
            params=overrides,
            client=client,
            settings=RolloutSettings(
                keyframe_budget=args.keyframes,
                keyframe_objects=args.keyframe_objects,
                verifier=not args.no_verifier,
                verifier_error_rate=args.verifier_error_rate,
            ),
            jobs=args.jobs,
            progress=not args.quiet,
        )
    except ScenarioError as error:
        return fail(f"--scenario: {error}")
    except (httpx.HTTPError, PbdagError) as error:
        return fail(f"--via-service: {error}")
    finally:
        if client is not None:
            client.close()
    rows = [row for row, _ in runs]
    results = [result for _, result in runs]
    written = write(
        rows,
        results,
        args.out,
        args.seeds,
        args.budgets,
        overrides,
        code_version(),
        world_note(args),
        profile=args.profile,
    )
    for written_path in written:
        print(f"wrote {written_path}")
    return 0


def loadable(given: list[Path] | None, defaults: list[str]) -> list[Path] | None:
    """The scenario files to run. A shipped one that cannot load here (the real sequence it
    reads is not beside this clone) is left out with a note; a given one that cannot load is
    an error (None), and so is having none left to run."""
    from sim.scenario import ScenarioError, load_scenario

    paths = given or [SCENARIOS_DIR / name for name in defaults]
    kept = []
    for path in paths:
        try:
            load_scenario(path)
        except (ScenarioError, OSError) as error:
            if given:
                print(f"pbdag eval: --scenario: {path}: {error}", file=sys.stderr)
                return None
            print(f"pbdag eval: leaving out {path.name}: {error}", file=sys.stderr)
            continue
        kept.append(path)
    if not kept:
        print(f"pbdag eval: no shipped scenario loads from {SCENARIOS_DIR}", file=sys.stderr)
        return None
    return kept


def run(args: argparse.Namespace) -> int:
    """Run a protocol and write its report."""
    # Imported here so that `pbdag serve` never loads the simulator (open3d) just to build its CLI.

    from evaluation.methods import (
        ABLATION_METHODS,
        DYNAMIC_METHODS,
        FIXTURE_METHODS,
        method_named,
        with_params,
    )
    from evaluation.protocols import run_protocol
    from evaluation.report import write_report
    from evaluation.tables import console_summary
    from evaluation.world_intervals import interval_table

    scenarios = world_paths(args, DEFAULT_SCENARIOS[args.protocol])
    if scenarios is None:
        return 2
    catalogue = {
        "dynamic": DYNAMIC_METHODS,
        "fixtures": FIXTURE_METHODS,
        "ablation": ABLATION_METHODS,
    }[args.protocol]
    protocol = "fixtures" if args.protocol == "fixtures" else "dynamic"  # the metrics
    methods = (
        [method_named(name, catalogue) for name in args.methods]
        if args.methods
        else list(catalogue)
    )
    try:
        overrides = parsed_params(args.params)
    except ValueError as error:
        print(f"pbdag eval: --params: {error}", file=sys.stderr)
        return 2
    if overrides:
        methods = with_params(methods, overrides)
    try:
        scenario_overrides = scenario_changes(args.scenario_overrides, scenarios)
    except ValueError as error:
        print(f"pbdag eval: --scenario-overrides: {error}", file=sys.stderr)
        return 2
    if args.via_service and args.jobs > 1:
        print("pbdag eval: --jobs: runs through --via-service go one at a time", file=sys.stderr)
        return 2
    client = service_client(args.via_service, args.token)
    try:
        rows = run_protocol(
            protocol,
            scenarios,
            args.seeds,
            methods,
            via_service=client,
            progress=not args.quiet,
            frames=args.frames,
            jobs=args.jobs,
            scenario_overrides=scenario_overrides,
        )
    finally:
        if client is not None:
            client.close()
    written = write_report(
        protocol, rows, args.out, args.seeds, overrides, world_note(args), scenario_overrides
    )
    print(console_summary(protocol, rows))
    if args.generated is not None:
        print(interval_table(protocol, rows))
    if args.protocol == "ablation":
        from evaluation.ablation import write_effects

        print(write_effects(rows, args.out))
    for path in written:
        print(f"wrote {path}")
    return 0
