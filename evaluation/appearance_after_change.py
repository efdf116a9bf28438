"""What appearance says about a carried object, batch by batch: does a sighting after the change
still prefer the object's own track over every other track of its class?

For every move and transfer of a development evaluation's event trace whose object had an
identity before the change (`identity_before`), each batch that detects the object gives its
margin: the mean over the batch's detections of the object of cos(detection, own track) minus
the best cos(detection, other track), against the tracks' appearance as the batch found it.
For a swap (two transfers of one class in one frame), the other track is the partner's; for a
single carry, the best other object track of the detection's label. A margin above 0 means
appearance alone points at the right identity; a re-identification needs it past
`fallback_margin` (0.05).

The margins before the change show how well the pair is told apart at rest (the view part of a
look, `sim.appearance`, is shared with the track); the first batch after shows the evidence a
hand-over or a swap test would have, before the track absorbs the new sightings.

Development worlds only: it reads the results of `pbdag eval dynamic --split dev` and refuses
any other split (evaluation/README.md).

    python -m evaluation.appearance_after_change evaluation/results/dev/results.json
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from api_schema import BatchIn
from codec.observations import decode_batch
from core.decide import decide
from core.events import SceneCreated
from core.evolve import evolve, fold
from core.params import Params
from core.state import SceneState
from evaluation.methods import ABLATION_METHODS, OURS, method_named
from evaluation.protocols import make_stream
from sim.stream import SimFrame

Vector = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Case:
    """One carried object: its own track, and the partner's track when it was swapped."""

    object_id: str
    frame: int  # the frame of the change
    own: str
    partner: str | None = None


def cases_of(trace: Sequence[Mapping[str, Any]]) -> list[Case]:
    """The moves and transfers of an event trace whose object had an identity before."""
    by_frame: dict[tuple[int, str], list[Mapping[str, Any]]] = {}
    for entry in trace:
        if entry["type"] in ("move", "transfer"):
            by_frame.setdefault((entry["frame"], entry["type"]), []).append(entry)
    cases = []
    for (frame, kind), entries in sorted(by_frame.items()):
        known = [e for e in entries if e["identity_before"]]
        swap = kind == "transfer" and len(entries) == 2 and len(known) == 2
        for entry in known:
            partner = next(e for e in known if e is not entry)["identity_before"] if swap else None
            cases.append(Case(entry["object"], frame, entry["identity_before"], partner))
    return cases


def margin(detections: Sequence[Vector], own: Vector, others: Sequence[Vector]) -> float | None:
    """Mean over the detections of cos(detection, own) - max cos(detection, other); None
    without detections or without another track to compare with."""
    if not detections or not others:
        return None
    rows = np.array([d / np.linalg.norm(d) for d in detections])
    best_other = (rows @ np.array(others).T).max(axis=1)
    return float(np.mean(rows @ own - best_other))


def _others(state: SceneState, case: Case, label: str) -> list[Vector]:
    if case.partner is not None:
        partner = state.tracks.get(case.partner)
        vector = None if partner is None else partner.embedding()
        return [] if vector is None else [vector]
    vectors = []
    for track_id, track in state.tracks.items():
        vector = track.embedding()
        skip = track_id == case.own or track.kind != "object"
        if not skip and vector is not None and track.class_evidence and track.label == label:
            vectors.append(vector)
    return vectors


def _sightings(frames: Sequence[SimFrame], object_id: str) -> tuple[list[Vector], str | None]:
    """The appearance of every detection of the object in the frames, and its label."""
    vectors, label = [], None
    for frame in frames:
        for detection in frame.detections:
            if detection.object_id == object_id and detection.embedding is not None:
                vectors.append(detection.embedding)
                label = detection.label
    return vectors, label


def margins(world: Path, seed: int, cases: Sequence[Case]) -> dict[Case, list[tuple[int, float]]]:
    """Per case, (batch's last frame, margin) of every batch that detected its object."""
    method = method_named(OURS, ABLATION_METHODS)
    params = Params.from_dict(method.params)
    stream = make_stream(world, seed)
    state = evolve(SceneState(), SceneCreated(name=world.stem, params=params.to_dict()))
    found: dict[Case, list[tuple[int, float]]] = {case: [] for case in cases}
    start = 0
    for last_frame, body in stream.batches:
        frames = stream.run.frames[start : last_frame + 1]
        for case in cases:
            own = state.tracks.get(case.own)
            own_vector = None if own is None else own.embedding()
            seen, label = _sightings(frames, case.object_id)
            if own_vector is None or label is None:
                continue
            value = margin(seen, own_vector, _others(state, case, label))
            if value is not None:
                found[case].append((last_frame, value))
        state = fold(state, decide(state, decode_batch(BatchIn.model_validate(body)), params))
        start = last_frame + 1
    return found


def rows_of(world: str, found: Mapping[Case, list[tuple[int, float]]]) -> Iterable[str]:
    """Table rows: the median margin before the change, the first batch after, the rest."""
    for case, values in found.items():
        before = [v for frame, v in values if frame < case.frame]
        after = [v for frame, v in values if frame > case.frame]
        kind = "swap" if case.partner else "carry"
        at_rest = f"{np.median(before):+.3f}" if before else "-"
        first = f"{after[0]:+.3f}" if after else "-"
        later = f"{np.median(after[1:]):+.3f}" if len(after) > 1 else "-"
        yield f"| {world} | {case.object_id} | {kind} | {at_rest} | {first} | {later} |"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m evaluation.appearance_after_change", description=__doc__
    )
    parser.add_argument("results", type=Path, help="results.json of `pbdag eval dynamic`, dev")
    args = parser.parse_args(argv)
    try:
        document = json.loads(args.results.read_text())
    except (OSError, ValueError) as error:
        print(f"appearance_after_change: {args.results}: {error}", file=sys.stderr)
        return 2
    split = (document.get("generated_worlds") or {}).get("split")
    if split != "dev":
        print(
            f"appearance_after_change: {args.results}: split {split!r}; only dev worlds are traced",
            file=sys.stderr,
        )
        return 2
    print("| world | object | change | margin at rest | first batch after | later |")
    print("|---|---|---|---|---|---|")
    for run in document["runs"]:
        cases = cases_of(run["event_trace"])
        if cases:
            found = margins(Path(run["scenario_file"]), run["seed"], cases)
            for row in rows_of(run["scenario"], found):
                print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
