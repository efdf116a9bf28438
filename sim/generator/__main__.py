"""Write (or print) the YAML of a generated world: `python -m sim.generator --seed S [--active]`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim.generator.files import world_yaml
from sim.generator.knobs import split_seeds
from sim.generator.world import GenerationError


def main(argv: list[str] | None = None) -> int:
    """Generate one world and write its scenario YAML to --out (or print it)."""
    parser = argparse.ArgumentParser(
        prog="python -m sim.generator",
        description="Write the scenario YAML of a procedurally generated world. Development "
        f"seeds start at {split_seeds('dev', 1)[0]} (traces and tuning), test seeds at "
        f"{split_seeds('test', 1)[0]} (reporting only).",
    )
    parser.add_argument("--seed", type=int, required=True, help="world seed (>= 0)")
    parser.add_argument("--active", action="store_true", help="an active-protocol world")
    parser.add_argument("--out", type=Path, help="YAML file to write (default: print)")
    arguments = parser.parse_args(argv)
    if arguments.seed < 0:
        parser.error("--seed must be >= 0")
    try:
        _, text = world_yaml(arguments.seed, active=arguments.active)
    except GenerationError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if arguments.out is None:
        sys.stdout.write(text)
    else:
        arguments.out.parent.mkdir(parents=True, exist_ok=True)
        arguments.out.write_text(text, encoding="utf-8")
        print(f"wrote {arguments.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
