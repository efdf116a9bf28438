"""Generated worlds for the evaluation: the development and the test split.

`pbdag eval dynamic|fixtures|active --generated N --split dev|test` writes the first N worlds of
the split as scenario files under `<out>/worlds/` (so each one can be inspected, replayed and
checked with the coverage tool) and runs the protocol on them. Development seeds are for traces
and tuning; test seeds are for reporting only (evaluation/README.md, "Splits").
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Literal

from sim.generator import split_seeds
from sim.generator.files import world_yaml

Split = Literal["dev", "test"]
SPLITS: tuple[Split, ...] = ("dev", "test")
# One stream per generated world: the worlds, not detector seeds, are the unit the confidence
# intervals resample. The stream seed is fixed so a world's file and its stream name one run.
GENERATED_STREAM_SEED = 7


def world_files(count: int, split: Split, out: Path, *, active: bool = False) -> list[Path]:
    """Write the split's first `count` worlds as YAML under `out/worlds/`; their paths in order.

    A file already there with the same content is kept as it is (reruns do not rewrite it).
    """
    if count < 1:
        raise ValueError(f"--generated: {count} is not a positive number of worlds")
    folder = out / "worlds"
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for seed in split_seeds(split, count):
        name, text = world_yaml(seed, active=active)
        path = folder / f"{name}.yaml"
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
        paths.append(path)
    print(f"pbdag eval: {count} generated {split} worlds in {folder}", file=sys.stderr)
    return paths
