"""Fixture evidence as open-vocabulary segmenters give it: per-view scores, merges, splits, parts.

Each visible fixture is segmented with the persistent luck of `sim.detectability` (a fixture
missed in one view tends to be missed in the next) and the errors real segmenters make with
furniture:

* Per-view class scores. The true class scores about 0.60 with per-view noise; its rival (the
  scenario's confusable partner, else the furniture class it is most often taken for) moves
  from view to view with the fixture's persistent latent, and leads in a share of views that is
  the fixture's own ambiguity: a Beta draw seeded by its id, of mean `wrong_top_rate`. So a
  clear table almost never reads otherwise, while an ambiguous desk reads "table" over
  stretches of views.
* Masks covering only part of the piece, and masks spilling into the fixture next to it.
* Two adjacent fixtures (a nightstand against a bed, a cabinet against a counter) segmented as
  one mask carrying the larger one's scores, over stretches of views (`merge_rate`).
* A long fixture (a counter run, a dining table) segmented as two halves (`split_rate`), each
  with its own score noise.
* Persistent hallucinations at fixed places (`sim.spurious`: a rug, a stretch of wall, a chair).
"""

from __future__ import annotations

import functools
import itertools
import math
import zlib
from collections.abc import Sequence

import numpy as np
from scipy.special import ndtri
from scipy.stats import beta

from sim.detectability import DetectorLuck
from sim.detector import SimDetection, fixture_class_scores
from sim.detector_settings import FixtureDetectorSpec
from sim.masks import bleed, partial, principal_angle, split
from sim.render import Render
from sim.spurious import SpuriousSite, spurious_masks, spurious_scores
from sim.world import Box, World

# The furniture class a fixture is most often taken for when the scenario names no partner.
FURNITURE_RIVALS = {
    "table": "desk",
    "desk": "table",
    "counter": "cabinet",
    "cabinet": "shelf",
    "shelf": "cabinet",
    "bed": "sofa",
    "sofa": "bed",
}
# The rival's lead over the true class is this times (Phi^-1(ambiguity) - latent), the latent
# N(0, 1): it leads in exactly the ambiguity's share of views. A fixture read wrong in 0.5 % of
# views keeps its rival 0.26 below in a median view, as far as the distractors (0.20-0.35
# against 0.60); one read wrong in 5 %, 0.16 below; in 30 %, 0.05 below.
RIVAL_SPREAD = 0.10
# Beta concentration floor: rates of exactly 0 or 1 would make Phi^-1 infinite.
RATE_FLOOR = 1e-4
# Two fixtures may be segmented as one when their tops differ by at most this much.
MERGE_MAX_TOP_STEP_M = 0.25


def _corners(box: Box) -> np.ndarray:
    """The four footprint corners of a (turned) box, in order."""
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    half_x, half_y = box.size[0] / 2, box.size[1] / 2
    local = [(-half_x, -half_y), (half_x, -half_y), (half_x, half_y), (-half_x, half_y)]
    return np.array(
        [
            (box.center[0] + cos_yaw * x - sin_yaw * y, box.center[1] + sin_yaw * x + cos_yaw * y)
            for x, y in local
        ]
    )


def over_footprint(x: float, y: float, box: Box) -> bool:
    """Whether the point (x, y) lies over the (turned) box's footprint."""
    dx, dy = x - box.center[0], y - box.center[1]
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    along, across = cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy
    return bool(abs(along) <= box.size[0] / 2 + 1e-9 and abs(across) <= box.size[1] / 2 + 1e-9)


def _segment_distance(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    edge = end - start
    along = float(np.clip(np.dot(point - start, edge) / max(float(edge @ edge), 1e-12), 0, 1))
    return float(np.linalg.norm(point - (start + along * edge)))


def footprint_gap(first: Box, second: Box) -> float:
    """Planar distance between two fixtures' footprints (0 when they touch or overlap)."""
    corners = (_corners(first), _corners(second))
    inside = any(over_footprint(x, y, second) for x, y in corners[0])
    if inside or any(over_footprint(x, y, first) for x, y in corners[1]):
        return 0.0
    return min(
        _segment_distance(point, edges[i], edges[(i + 1) % 4])
        for points, edges in (corners, corners[::-1])
        for point in points
        for i in range(4)
    )


def adjacent_pairs(fixtures: Sequence[Box], max_gap_m: float) -> list[tuple[str, str]]:
    """Fixture pairs a segmenter may take for one piece: close footprints, tops at one height."""
    return [
        (a.id, b.id)
        for a, b in itertools.combinations(fixtures, 2)
        if abs(a.top_z - b.top_z) <= MERGE_MAX_TOP_STEP_M and footprint_gap(a, b) <= max_gap_m
    ]


def fixture_luck_keys(
    fixtures: Sequence[Box], pairs: Sequence[tuple[str, str]] = (), sites: int = 0
) -> list[str]:
    """The latent keys the segmenter reads: segmented, rival's lead, split; merges; sites."""
    keys = [f"{kind}/{f.id}" for f in fixtures for kind in ("fixture", "top", "split")]
    keys += [f"merge/{a}/{b}" for a, b in pairs]
    return keys + [f"spurious/{index}" for index in range(sites)]


@functools.lru_cache(maxsize=1024)
def ambiguity_of(fixture_id: str, mean: float, concentration: float) -> float:
    """Share of views in which a fixture's rival leads: an id-seeded Beta draw of `mean`.

    Concentration 0 gives every fixture the mean itself.
    """
    if concentration <= 0 or mean <= 0 or mean >= 1:
        return min(max(mean, 0.0), 1.0)
    uniform = np.random.default_rng(zlib.crc32(f"fixture/ambiguity/{fixture_id}".encode())).random()
    return float(beta.ppf(uniform, mean * concentration, (1 - mean) * concentration))


class FixtureSegmenter:
    """The fixture half of the realistic detector."""

    def __init__(
        self,
        spec: FixtureDetectorSpec,
        confusable: Sequence[Sequence[str]],
        fixtures: Sequence[Box] = (),
        sites: Sequence[SpuriousSite] = (),
    ) -> None:
        self.spec = spec
        self.partners = {
            label: [other for other in group if other != label]
            for group in confusable
            for label in group
        }
        self.pairs = adjacent_pairs(fixtures, spec.merge_gap_m)
        self.sites = tuple(sites)

    def rival(self, fixture: Box) -> str:
        """The class a wrong view puts on top: a confusable partner, else its furniture rival."""
        for partner in self.partners.get(fixture.label, []):
            return partner
        return FURNITURE_RIVALS.get(fixture.label, "table")

    def base_scores(self, fixture: Box) -> dict[str, float]:
        """A fixture's scores before a view's noise: its class, distractors, its rival (or the
        scenario's override); the same labels in every view, so the draws per view are fixed."""
        scores = fixture_class_scores(fixture)
        if self.spec.ambiguity is not None and fixture.id in self.spec.ambiguity:
            scores.update(self.spec.ambiguity[fixture.id])
        else:
            scores.setdefault(self.rival(fixture), 0.0)  # set per view by `view_scores`
        return scores

    def view_scores(self, fixture: Box, noise: np.ndarray, luck: DetectorLuck) -> dict[str, float]:
        """One view's class scores of a fixture, best first (`noise`: one draw per base label).

        Without an override, the rival's score is the true class's plus its lead this view.
        """
        spec = self.spec
        base = self.base_scores(fixture)
        noisy = dict(zip(base, np.fromiter(base.values(), float) + noise, strict=True))
        if spec.ambiguity is None or fixture.id not in spec.ambiguity:
            rate = ambiguity_of(fixture.id, spec.wrong_top_rate, spec.ambiguity_concentration)
            threshold = ndtri(min(max(rate, RATE_FLOOR), 1 - RATE_FLOOR))
            lead = RIVAL_SPREAD * (threshold - luck.latent(f"top/{fixture.id}"))
            noisy[self.rival(fixture)] = noisy[fixture.label] + lead
        clipped = {label: min(1.0, max(0.0, float(score))) for label, score in noisy.items()}
        return dict(sorted(clipped.items(), key=lambda pair: -pair[1]))

    def detect(
        self, render: Render, world: World, rng: np.random.Generator, luck: DetectorLuck
    ) -> list[SimDetection]:
        """Fixture masks with class scores, best first; merged, split and spurious ones too."""
        spec = self.spec
        visible = np.bincount(
            render.fixture_instance.ravel() + 1, minlength=len(world.fixtures) + 1
        )[1:]
        found: dict[str, SimDetection] = {}
        for index, fixture in enumerate(world.fixtures):
            if visible[index] < spec.min_visible_pixels:
                continue
            if not luck.passes(f"fixture/{fixture.id}", spec.recall):
                continue
            # A fixed number of draws per segmented fixture keeps the stream aligned.
            noise = rng.normal(0.0, spec.score_noise, size=(2, len(self.base_scores(fixture))))
            cut, keep, angle = rng.random(), rng.uniform(*spec.partial_keep), rng.uniform(0, np.pi)
            spill, spill_px = (
                rng.random(),
                int(rng.integers(spec.bleed_px[0], spec.bleed_px[1] + 1)),
            )
            mask = render.fixture_instance == index
            if cut < spec.partial_rate:
                mask = partial(mask, keep, angle)
            if spill < spec.bleed_rate:
                neighbours = (render.fixture_instance >= 0) & (render.fixture_instance != index)
                mask = bleed(mask, neighbours, spill_px)
            if mask.sum() < spec.min_visible_pixels:
                continue
            ranked = self.view_scores(fixture, noise[0], luck)
            label, score = next(iter(ranked.items()))
            found[fixture.id] = SimDetection(
                fixture.id, label, score, mask, None, "fixture", ranked
            )
            long = max(fixture.size[:2]) >= spec.split_min_length_m
            if long and luck.passes(f"split/{fixture.id}", spec.split_rate):
                found[f"{fixture.id}#2"] = self._split(found, fixture, noise[1], luck)
        detections = self._merged(found, luck)
        for site, mask in spurious_masks(self.sites, render, world, spec.min_visible_pixels):
            if luck.passes(f"spurious/{site.index}", spec.spurious_recall):
                ranked = spurious_scores(site, rng, spec.score_noise)
                label, score = next(iter(ranked.items()))
                detections.append(
                    SimDetection(site.id, label, score, mask, None, "fixture", ranked)
                )
        return detections

    def _split(
        self, found: dict[str, SimDetection], fixture: Box, noise: np.ndarray, luck: DetectorLuck
    ) -> SimDetection:
        """Cut the fixture's detection in two across its longest image extent; the second half
        gets its own score noise. Returns the second half and shortens the first in place."""
        whole = found[fixture.id]
        first, second = split(whole.mask, principal_angle(whole.mask))
        found[fixture.id] = SimDetection(
            fixture.id, whole.label, whole.score, first, None, "fixture", whole.class_scores
        )
        ranked = self.view_scores(fixture, noise, luck)
        label, score = next(iter(ranked.items()))
        return SimDetection(fixture.id, label, score, second, None, "fixture", ranked)

    def _merged(self, found: dict[str, SimDetection], luck: DetectorLuck) -> list[SimDetection]:
        """Adjacent fixtures segmented as one mask, with the larger one's scores and id."""
        for first, second in self.pairs:
            if first not in found or second not in found:
                continue  # one of them unseen, or already merged into a third
            if not luck.passes(f"merge/{first}/{second}", self.spec.merge_rate):
                continue
            keeper, other = sorted((found[first], found[second]), key=lambda d: -int(d.mask.sum()))
            found[keeper.object_id] = SimDetection(
                keeper.object_id,
                keeper.label,
                keeper.score,
                keeper.mask | other.mask,
                None,
                "fixture",
                keeper.class_scores,
            )
            del found[other.object_id]
        return [d for d in found.values() if d.mask.sum() >= self.spec.min_visible_pixels]
