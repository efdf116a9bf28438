"""Fixture evidence as open-vocabulary segmenters give it: partial tops, bleeding, wrong classes.

Each visible fixture is segmented with the persistent luck of `sim.detectability` (a fixture
missed in one view tends to be missed in the next), class scores around its true class, and the
errors real segmenters make with furniture: a mask covering only part of the piece, a mask
spilling into the fixture standing next to it, and, over stretches of views, a wrong class on
top (a desk read as a table: the scenario's confusable partner, else the fixture's strongest
distractor).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sim.detectability import DetectorLuck
from sim.detector import SimDetection, fixture_class_scores
from sim.detector_settings import FixtureDetectorSpec
from sim.masks import bleed, partial
from sim.render import Render
from sim.world import Box, World

# When a view's top class is wrong, the wrong class leads the true one by a margin in this range.
WRONG_TOP_LEAD = (0.02, 0.10)


def fixture_luck_keys(fixtures: Sequence[Box]) -> list[str]:
    """The latent keys the segmenter reads: being segmented, and a wrong top class."""
    return [f"{kind}/{fixture.id}" for fixture in fixtures for kind in ("fixture", "top")]


class FixtureSegmenter:
    """The fixture half of the realistic detector."""

    def __init__(self, spec: FixtureDetectorSpec, confusable: Sequence[Sequence[str]]) -> None:
        self.spec = spec
        self.partners = {
            label: [other for other in group if other != label]
            for group in confusable
            for label in group
        }

    def _rival(self, fixture: Box, scores: dict[str, float]) -> str:
        """The class a wrong view puts on top: a confusable partner, else the best distractor."""
        for partner in self.partners.get(fixture.label, []):
            return partner
        distractors = [label for label in scores if label != fixture.label]
        return max(distractors, key=lambda label: scores[label])

    def detect(
        self, render: Render, world: World, rng: np.random.Generator, luck: DetectorLuck
    ) -> list[SimDetection]:
        """Fixture masks with class scores, best first."""
        spec = self.spec
        visible = np.bincount(
            render.fixture_instance.ravel() + 1, minlength=len(world.fixtures) + 1
        )[1:]
        detections = []
        for index, fixture in enumerate(world.fixtures):
            if visible[index] < spec.min_visible_pixels:
                continue
            if not luck.passes(f"fixture/{fixture.id}", spec.recall):
                continue
            scores = fixture_class_scores(fixture)
            if spec.ambiguity is not None:
                scores.update(spec.ambiguity.get(fixture.id, {}))
            # A fixed number of draws per segmented fixture keeps the stream aligned.
            noise = rng.normal(0.0, spec.score_noise, size=len(scores))
            lead = rng.uniform(*WRONG_TOP_LEAD)
            cut, keep, angle = (
                rng.random(),
                rng.uniform(*spec.partial_keep),
                rng.uniform(0, math.pi),
            )
            spill, spill_px = (
                rng.random(),
                int(rng.integers(spec.bleed_px[0], spec.bleed_px[1] + 1)),
            )
            noisy = np.clip(np.fromiter(scores.values(), dtype=np.float64) + noise, 0.0, 1.0)
            class_scores = dict(zip(scores, noisy.tolist(), strict=True))
            if luck.passes(f"top/{fixture.id}", spec.wrong_top_rate):
                rival = self._rival(fixture, class_scores)
                class_scores[rival] = min(1.0, class_scores[fixture.label] + lead)
            ranked = dict(sorted(class_scores.items(), key=lambda pair: -pair[1]))
            mask = render.fixture_instance == index
            if cut < spec.partial_rate:
                mask = partial(mask, keep, angle)
            if spill < spec.bleed_rate:
                neighbours = (render.fixture_instance >= 0) & (render.fixture_instance != index)
                mask = bleed(mask, neighbours, spill_px)
            if mask.sum() < spec.min_visible_pixels:
                continue
            label, score = next(iter(ranked.items()))
            detections.append(SimDetection(fixture.id, label, score, mask, None, "fixture", ranked))
        return detections
