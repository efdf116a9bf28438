"""Bootstrap confidence intervals over worlds, for the generated splits.

The unit of resampling is one world's run (a scenario-seed stream): the worlds are a sample of
the generator's distribution, and what a reader wants to know is how much a figure would move
on another sample of the same size. Means (IDF1, switches, F1) are resampled as means; pooled
ratios (event recall, false absence) as the ratio of the resampled sums, the way the tables pool
them. Percentile intervals (`scipy.stats.bootstrap`), 95%, 2,000 resamples, a fixed seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import bootstrap

LEVEL = 0.95
RESAMPLES = 2000
SEED = 20261201


@dataclass(frozen=True)
class Interval:
    """A statistic over worlds and its bootstrap interval."""

    value: float
    low: float
    high: float
    worlds: int

    def as_json(self) -> dict[str, float | int]:
        return {"value": self.value, "low": self.low, "high": self.high, "worlds": self.worlds}


def _interval(samples: tuple[np.ndarray, ...], statistic: Any, value: float) -> Interval:
    worlds = len(samples[0])
    if worlds < 2 or all(np.ptp(sample) == 0 for sample in samples):
        return Interval(value, value, value, worlds)  # nothing varies: the interval is the point
    result = bootstrap(
        samples,
        statistic,
        paired=True,
        vectorized=False,
        confidence_level=LEVEL,
        n_resamples=RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(SEED),
    )
    low, high = result.confidence_interval
    return Interval(value, float(low), float(high), worlds)


def mean_interval(values: Sequence[float]) -> Interval:
    """The mean over worlds with its interval."""
    data = np.asarray(values, dtype=float)
    return _interval((data,), np.mean, float(data.mean()))


def ratio_interval(numerators: Sequence[float], denominators: Sequence[float]) -> Interval:
    """sum(numerators) / sum(denominators) over worlds with its interval (0 when nothing counts)."""
    top = np.asarray(numerators, dtype=float)
    bottom = np.asarray(denominators, dtype=float)

    def pooled(first: np.ndarray, second: np.ndarray) -> float:
        total = second.sum()
        return float(first.sum() / total) if total else 0.0

    return _interval((top, bottom), pooled, pooled(top, bottom))


def mean_difference_interval(first: Sequence[float], second: Sequence[float]) -> Interval:
    """mean(first - second) over paired worlds with its interval (the worlds resampled once
    for both, so what they share cancels)."""
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)

    def difference(x: np.ndarray, y: np.ndarray) -> float:
        return float((x - y).mean())

    return _interval((a, b), difference, difference(a, b))


def ratio_difference_interval(
    first: tuple[Sequence[float], Sequence[float]], second: tuple[Sequence[float], Sequence[float]]
) -> Interval:
    """The difference of two pooled ratios (numerators, denominators) over paired worlds."""
    arrays = tuple(np.asarray(values, dtype=float) for values in (*first, *second))

    def difference(n1: np.ndarray, d1: np.ndarray, n2: np.ndarray, d2: np.ndarray) -> float:
        top = float(n1.sum() / d1.sum()) if d1.sum() else 0.0
        bottom = float(n2.sum() / d2.sum()) if d2.sum() else 0.0
        return top - bottom

    return _interval(arrays, difference, difference(*arrays))


def excludes_zero(interval: Interval) -> bool:
    """The interval, over two worlds or more, lies wholly on one side of 0: a measurable
    difference."""
    return interval.worlds >= 2 and (interval.low > 0 or interval.high < 0)


def short(value: float) -> str:
    """.833 rather than 0.833 (the paper's format); other numbers to three decimals."""
    text = f"{value:.3f}"
    return text[1:] if text.startswith("0.") else text.replace("-0.", "-.")


def spelled(interval: Interval) -> str:
    """`.905 [.880, .927]`, the format of the generated tables."""
    return f"{short(interval.value)} [{short(interval.low)}, {short(interval.high)}]"


def signed(interval: Interval) -> str:
    """`+.012 [-.003, +.027]`: a difference, its sign always written."""

    def one(value: float) -> str:
        text = short(abs(value))
        return ("-" if value < 0 else "+") + text

    return f"{one(interval.value)} [{one(interval.low)}, {one(interval.high)}]"
