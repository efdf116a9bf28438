"""The figures the appearance model gives: `python -m sim.appearance_report [--distinctiveness D]`.

Random views of many instances of one class (mugs), of a confusable class (cups), of an unrelated
class (books) and clutter blobs, embedded as the realistic detector embeds them (a share of the
detections cropped by a partial mask). It prints cosine percentiles per kind of pair, how often
the paper's 0.78 appearance gate is crossed the wrong way, and the choice between an object's own
track and another same-class object's track for a new detection of the object (undecided when
the two cosines are within the paper's 0.05 margin).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.appearance import AppearanceModel
from sim.detector_settings import AppearanceSpec, MaskSpec

GATE = 0.78  # the paper's appearance gate (section 3.3, "Type-specific association")
MARGIN = 0.05  # the paper's fallback margin between the best and the second appearance match
PARTIAL_LOSS = 0.08  # what a cropped mask moves to noise (`sim.detector_model`)
INSTANCES = 40  # mugs (and 8 cups and 8 books) whose looks are drawn from the distribution
VIEWS = 24  # random views per instance
TRACK_VIEWS = 10  # detections averaged into a track's embedding (the paper averages by count)
TRIALS = 2000
PERCENTILES = (5, 25, 50, 75, 95)


@dataclass(frozen=True)
class Figures:
    """Cosines per kind of pair, and the track choice tally."""

    cosines: dict[str, np.ndarray]
    # (right, wrong, undecided) per case: two distinct-looking mugs or a look-alike pair, the
    # detection taken where its own track was built or where the other's was (carried there)
    choices: dict[str, tuple[int, int, int]]


def _direction(rng: np.random.Generator) -> np.ndarray:
    """A robot's view of an object on furniture: any side, 5-35 degrees from above."""
    azimuth, elevation = rng.uniform(0, 2 * math.pi), math.radians(rng.uniform(5, 35))
    return np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )


def _views(
    model: AppearanceModel,
    key: str,
    label: str,
    count: int,
    rng: np.random.Generator,
    place: str = "",
) -> np.ndarray:
    """`count` detections of one thing from random views at one place, a share of them cropped."""
    cropped = MaskSpec().partial_rate + MaskSpec().split_rate
    rows = []
    for _ in range(count):
        loss = PARTIAL_LOSS if rng.random() < cropped else 0.0
        embedding = model.embed(key, label, _direction(rng), rng, loss, place or f"on/{key}")
        assert embedding is not None
        rows.append(embedding)
    return np.array(rows)


def _pairs(first: np.ndarray, second: np.ndarray | None = None) -> np.ndarray:
    """Cosines of every pair of rows (within one set when `second` is None)."""
    if second is None:
        gram = first @ first.T
        return np.asarray(gram[np.triu_indices(len(first), k=1)])
    return np.asarray(first @ second.T).ravel()


def _track(views: np.ndarray) -> np.ndarray:
    """A track's appearance: its detections averaged, then unit-normalized (the paper's)."""
    mean = np.asarray(views.mean(axis=0))
    return np.asarray(mean / np.linalg.norm(mean))


def measure(spec: AppearanceSpec, seed: int = 0, trials: int = TRIALS) -> Figures:
    """Every figure of the report for one appearance setting."""
    mugs = [f"mug_{index}" for index in range(INSTANCES)]
    # The last eight mugs come in look-alike pairs (four sets of two).
    sets = tuple((mugs[i], mugs[i + 1]) for i in range(INSTANCES - 8, INSTANCES, 2))
    model = AppearanceModel(dataclasses.replace(spec, look_alike=sets), [("cup", "mug")])
    rng = np.random.default_rng(seed)
    views = {key: _views(model, key, "mug", VIEWS, rng) for key in mugs}
    cups = [_views(model, f"cup_{index}", "cup", VIEWS, rng) for index in range(8)]
    books = [_views(model, f"book_{index}", "book", VIEWS, rng) for index in range(8)]
    clutter = np.array([model.clutter(rng) for _ in range(VIEWS * 8)])
    alike = {key for group in sets for key in group}
    distinct = [key for key in mugs if key not in alike]
    cosines = {
        "same instance": np.concatenate([_pairs(views[key]) for key in mugs]),
        "same class, other instance": np.concatenate(
            [_pairs(views[a], views[b]) for i, a in enumerate(distinct) for b in distinct[i + 1 :]]
        ),
        "look-alike pair": np.concatenate([_pairs(views[a], views[b]) for a, b in sets]),
        "confusable class (mug-cup)": np.concatenate(
            [_pairs(views[mugs[i]], cup) for i, cup in enumerate(cups)]
        ),
        "unrelated class (mug-book)": np.concatenate(
            [_pairs(views[mugs[i]], book) for i, book in enumerate(books)]
        ),
        "clutter (mug-blob)": _pairs(np.concatenate([views[key] for key in mugs[:8]]), clutter),
    }
    pairs = [(distinct[i], distinct[j]) for i, j in _two_of(len(distinct), trials, rng)]
    alike_pairs = [sets[i] for i in rng.integers(len(sets), size=trials)]
    choices = {
        f"{kind}, {where}": _choices(model, chosen, rng, carried)
        for kind, chosen in (("distinct mugs", pairs), ("look-alike mugs", alike_pairs))
        for where, carried in (("seen where its track was built", False), ("carried", True))
    }
    return Figures(cosines, choices)


def _two_of(count: int, trials: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """`trials` ordered pairs of distinct indices below `count`."""
    picks = [rng.choice(count, size=2, replace=False) for _ in range(trials)]
    return [(int(first), int(second)) for first, second in picks]


def _choices(
    model: AppearanceModel,
    pairs: Sequence[tuple[str, str]],
    rng: np.random.Generator,
    carried: bool,
) -> tuple[int, int, int]:
    """Right, wrong and undecided choices between a detection's own track and another's.

    Each track averages detections taken where its object stands; the new detection of the
    first of each pair is taken there too, or (`carried`) where the second stood.
    """
    right = wrong = 0
    for own, other in pairs:
        own_track = _track(_views(model, own, "mug", TRACK_VIEWS, rng))
        other_track = _track(_views(model, other, "mug", TRACK_VIEWS, rng))
        place = f"on/{other}" if carried else f"on/{own}"
        detection = _views(model, own, "mug", 1, rng, place)[0]
        lead = float(detection @ own_track - detection @ other_track)
        right += lead > MARGIN
        wrong += lead < -MARGIN
    return right, wrong, len(pairs) - right - wrong


def render(figures: Figures, title: str) -> list[str]:
    """The report's lines for one setting."""
    lines = [title, f"{'pairs':32s} " + " ".join(f"p{p:<5d}" for p in PERCENTILES) + "  gate"]
    for name, values in figures.cosines.items():
        cells = " ".join(f"{v:.3f} " for v in np.percentile(values, PERCENTILES))
        crossed = (values < GATE).mean() if name == "same instance" else (values > GATE).mean()
        side = "below" if name == "same instance" else "above"
        lines.append(f"{name:32s} {cells} {100 * crossed:5.1f}% {side} {GATE}")
    lines.append(
        f"a new detection: its own track or another mug's? ({TRACK_VIEWS}-view tracks, "
        f"undecided within {MARGIN})"
    )
    for name, (right, wrong, undecided) in figures.choices.items():
        lines.append(f"  {name:50s} {right:5,} right {wrong:5,} wrong {undecided:5,} undecided")
    return lines


def main(argv: Sequence[str] | None = None) -> None:
    """Print the report for the defaults, then for each `--distinctiveness` value."""
    parser = argparse.ArgumentParser(prog="python -m sim.appearance_report", description=__doc__)
    parser.add_argument(
        "--distinctiveness",
        type=float,
        nargs="*",
        default=[],
        help="also report these values of detector.appearance.distinctiveness",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    default = AppearanceSpec()
    settings = [("defaults", default)]
    settings += [
        (f"distinctiveness {value}", dataclasses.replace(default, distinctiveness=value))
        for value in args.distinctiveness
    ]
    for name, spec in settings:
        print("\n".join(render(measure(spec, args.seed), f"\n{name}:")))


if __name__ == "__main__":
    main()
