"""Write (or print) the YAML of a generated world: `python -m sim.generator --seed S [--active]`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

from sim.generator.knobs import split_seeds
from sim.generator.world import GenerationError, generate_world_with_notes


def _flow(value: Any) -> str:
    """One value in YAML flow style on one line (`on` written bare, as the shipped files do)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6, sort_keys=False)
    return text.splitlines()[0].replace("'on':", "on:")


def to_yaml(mapping: dict[str, Any], header: str = "") -> str:
    """The scenario as YAML in the shipped files' layout: one line per list entry."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for key, value in mapping.items():
        if key == "trajectory":
            lines.append("trajectory:")
            lines += [f"  type: {value['type']}", f"  loops: {value['loops']}", "  points:"]
            lines += [f"    - {_flow(point)}" for point in value["points"]]
        elif key == "people":
            lines.append("people:")
            for person in value:
                lines.append(f"  - id: {person['id']}")
                if "detected_as" in person:
                    lines.append(f"    detected_as: {person['detected_as']}")
                lines.append("    keyframes:")
                lines += [f"      - {_flow(key_frame)}" for key_frame in person["keyframes"]]
        elif key == "detector":
            lines += [
                "detector:",
                "  labels:",
                f"    confusable: {_flow(value['labels']['confusable'])}",
            ]
        elif isinstance(value, list):
            lines.append(f"{key}:")
            lines += [f"  - {_flow(entry)}" for entry in value]
        else:
            lines.append(f"{key}: {_flow(value)}")
    return "\n".join(lines) + "\n"


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
        mapping, notes = generate_world_with_notes(arguments.seed, active=arguments.active)
    except GenerationError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    kind = "active" if arguments.active else "dynamic"
    header = [
        f"Generated {kind} world (python -m sim.generator --seed {arguments.seed}"
        f"{' --active' if arguments.active else ''}); regenerate rather than edit."
    ]
    for hard in notes.hard_events:
        header.append(
            f"{hard.kind}: {', '.join(hard.objects)} at {list(hard.frames)} ({hard.detail})"
        )
    text = to_yaml(mapping, "\n".join(header))
    if arguments.out is None:
        sys.stdout.write(text)
    else:
        arguments.out.parent.mkdir(parents=True, exist_ok=True)
        arguments.out.write_text(text, encoding="utf-8")
        print(f"wrote {arguments.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
