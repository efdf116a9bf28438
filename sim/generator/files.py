"""A generated world as a scenario file: the shipped files' layout, its hard events in the header."""

from __future__ import annotations

from typing import Any

import yaml

from sim.generator.world import generate_world_with_notes


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


def world_yaml(seed: int, *, active: bool = False) -> tuple[str, str]:
    """(name, YAML text) of world `seed`; the header says how to regenerate it and lists the
    hard events (raises GenerationError when no valid world can be drawn)."""
    mapping, notes = generate_world_with_notes(seed, active=active)
    kind = "active" if active else "dynamic"
    header = [
        f"Generated {kind} world (python -m sim.generator --seed {seed}"
        f"{' --active' if active else ''}); regenerate rather than edit."
    ]
    for hard in notes.hard_events:
        header.append(
            f"{hard.kind}: {', '.join(hard.objects)} at {list(hard.frames)} ({hard.detail})"
        )
    return str(mapping["name"]), to_yaml(mapping, "\n".join(header))
