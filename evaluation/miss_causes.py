"""What the visibility gate let through: the cause of every miss it counted against a published
object, read from the simulator's truth (issue of the gate ablation: does our gate do what the
paper's does, or are our worlds' misses not the occlusions it exists for?).

For each visible miss (`VisibleMiss`) of a published object track, the object it stood for is the
present truth object of its label nearest its published center, within 0.5 m. The batch's
frames then tell why the detector did not report it:

- `no object there`: nothing of its label stands there now (the miss is right);
- `detected`: a detection of the object was in the batch (the association did not match it);
- `hidden`: no pixel of it was visible in the batch's frames (occluded, or out of view): what the
  paper's gate exists to stop;
- `too small`: some pixels visible, fewer than the detector's minimum (a sliver, a far view);
- `in plain view`: visible at the detector's size and still not reported (a detector miss).

Development worlds only: `--split test` is refused, as traces from the test split motivate
nothing (evaluation/README.md).

    python -m evaluation.miss_causes --generated 6
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from core.events import VisibleMiss
from evaluation.change_metrics import PRESENCE_RADIUS_M
from evaluation.methods import ABLATION_METHODS, OURS, PAPERS, Method, method_named
from evaluation.protocols import Stream, make_stream, run_method
from evaluation.worlds import GENERATED_STREAM_SEED, world_files
from sim.truth import FrameTruth

CAUSES = ("no object there", "detected", "hidden", "too small", "in plain view")
DEFAULT_METHODS = (
    f"{PAPERS} w/o visibility gate",
    PAPERS,
    f"{PAPERS} + empty_place",
    f"{PAPERS} + missed_detection",
    OURS,
)


def miss_cause(
    truths: Sequence[FrameTruth],
    detected: Collection[str],
    min_pixels: int,
    label: str,
    center: Sequence[float],
) -> str:
    """Why a track published at `center` took a miss in a batch: `truths` are its frames'
    truth (the last one the frame the miss was counted at), `detected` the ids its detections
    stood for, `min_pixels` the detector's smallest mask."""
    candidates = [
        obj
        for obj in truths[-1].objects
        if obj.present and obj.label == label and _distance(obj.center, center) <= PRESENCE_RADIUS_M
    ]
    if not candidates:
        return "no object there"
    target = min(candidates, key=lambda obj: _distance(obj.center, center)).object_id
    if target in detected:
        return "detected"
    pixels = max(o.visible_pixels for t in truths for o in t.objects if o.object_id == target)
    if pixels == 0:
        return "hidden"
    return "too small" if pixels < min_pixels else "in plain view"


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return float(sum((x - y) ** 2 for x, y in zip(a, b, strict=True)) ** 0.5)


def causes_of(stream: Stream, method: Method) -> Counter[str]:
    """The causes of every visible miss `method` counted against a published object track."""
    result = run_method(stream, method, None, tqdm(disable=True))
    published = {}  # track id -> (label, center) as published before the frame
    by_frame = {p.frame_index: p for p in result.predictions}
    counts: Counter[str] = Counter()
    misses = [e for e in result.events if e.kind is VisibleMiss]
    min_pixels = stream.run.scenario.detector.min_visible_pixels
    for frame in sorted({e.frame for e in misses}):
        before = by_frame.get(frame - 1)
        published = {n.track_id: (n.label, n.center) for n in before.nodes} if before else {}
        for event in (e for e in misses if e.frame == frame):
            if event.track_id in published:
                label, center = published[event.track_id]
                frames = stream.run.frames[max(0, frame - 1) : frame + 1]
                truths = [f.truth for f in frames]
                detected = {d.object_id for f in frames for d in f.detections}
                counts[miss_cause(truths, detected, min_pixels, label, center)] += 1
    return counts


def table(counts: dict[str, Counter[str]]) -> str:
    """Misses per cause per method, with the share of those against a present object."""
    lines = [
        "| Method | " + " | ".join(CAUSES) + " | against a present object |",
        "|---" * (len(CAUSES) + 2) + "|",
    ]
    for name, by_cause in counts.items():
        present = sum(by_cause[c] for c in CAUSES[1:])
        shares = [
            f"{by_cause[c]}"
            + (f" ({by_cause[c] / present:.0%})" if c != CAUSES[0] and present else "")
            for c in CAUSES
        ]
        lines.append(f"| {name} | " + " | ".join(shares) + f" | {present} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m evaluation.miss_causes", description=__doc__)
    parser.add_argument("--generated", type=int, default=6, help="development worlds (default 6)")
    parser.add_argument("--split", default="dev", help="dev only: the test split is not traced")
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--out", type=Path, default=Path("evaluation/results/dev/miss_causes"))
    args = parser.parse_args(argv)
    if args.split != "dev":
        print("miss_causes: --split: only dev worlds are traced", file=sys.stderr)
        return 2
    try:
        methods = [method_named(name, ABLATION_METHODS) for name in args.methods]
    except KeyError as error:
        print(f"miss_causes: --methods: {error.args[0]}", file=sys.stderr)
        return 2
    counts: dict[str, Counter[str]] = {m.name: Counter() for m in methods}
    for path in tqdm(world_files(args.generated, "dev", args.out), desc="worlds"):
        stream = make_stream(path, GENERATED_STREAM_SEED)
        for method in methods:
            counts[method.name] += causes_of(stream, method)
    text = table(counts)
    args.out.mkdir(parents=True, exist_ok=True)
    document: dict[str, Any] = {"worlds": args.generated, "counts": counts}
    (args.out / "results.json").write_text(json.dumps(document, indent=2) + "\n")
    (args.out / "table.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
