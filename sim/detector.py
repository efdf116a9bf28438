"""The oracle 2D detector: ground-truth masks degraded only by flat recall, leakage and noise.

The streams of the evaluation use the realistic detector (`sim.detector_model`); this one stays
for hand-built test worlds and benchmarks that need exact, predictable detections.
"""

from __future__ import annotations

import functools
import zlib
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from sim.masks import leak
from sim.render import Render
from sim.world import Box, World

# The labels the simulated open-vocabulary segmenter is prompted with for fixtures.
FIXTURE_VOCABULARY = ("table", "desk", "counter", "bed", "shelf", "cabinet", "sofa")
TRUE_CLASS_SCORE = 0.60
DISTRACTOR_COUNT = 3
DISTRACTOR_SCORE_RANGE = (0.20, 0.35)


@dataclass(frozen=True, eq=False)
class SimDetection:
    """One detection plus the ground-truth object or fixture id the service never gets to see."""

    object_id: str
    label: str
    score: float
    mask: np.ndarray  # bool (H, W)
    embedding: np.ndarray | None  # float64 (dim,), not normalized once noise is added
    kind: str = "object"  # "object" or "fixture"
    class_scores: dict[str, float] | None = None  # label -> similarity, best first


@functools.lru_cache(maxsize=256)
def _unit_embedding(object_id: str, dim: int) -> np.ndarray:
    """Cached, read-only appearance vector (the public wrapper hands out copies)."""
    # crc32 rather than hash(): Python salts str hashes per process, crc32 is stable across runs.
    rng = np.random.default_rng(zlib.crc32(object_id.encode("utf-8")))
    vector = rng.standard_normal(dim)
    vector /= np.linalg.norm(vector)
    vector.setflags(write=False)
    return vector


def object_embedding(object_id: str, dim: int = 64) -> np.ndarray:
    """The object's fixed unit-norm appearance vector, derived from its id alone."""
    return _unit_embedding(object_id, dim).copy()


def detect(
    render: Render,
    world: World,
    rng: np.random.Generator,
    *,
    recall: float = 1.0,
    min_visible_pixels: int = 150,
    boundary_leak_px: int = 0,
    embedding_noise: float = 0.0,
    score: float = 0.9,
    embedding_dim: int | None = 64,
) -> list[SimDetection]:
    """Detections of the objects visible in `render` (fixtures: see `detect_fixtures`)."""
    visible_pixels = np.bincount(render.instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
    detections = []
    for index, box in enumerate(world.objects):
        if visible_pixels[index] < min_visible_pixels:
            continue
        # One draw per detectable object, in world order, keeps runs reproducible for a seed.
        if rng.random() >= recall:
            continue
        mask = render.instance == index
        if boundary_leak_px > 0:
            mask = leak(mask, boundary_leak_px)
        embedding = None
        if embedding_dim is not None:
            embedding = object_embedding(box.id, embedding_dim)
            if embedding_noise > 0:
                embedding += rng.normal(0.0, embedding_noise, size=embedding_dim)
        detections.append(SimDetection(box.id, box.label, score, mask, embedding))
    return detections


def fixture_class_scores(fixture: Box) -> dict[str, float]:
    """Noise-free class scores of a fixture: its own label on top, then id-seeded distractors."""
    # Seeded by the id, so a fixture is confused with the same classes in every frame and run,
    # the way a real open-vocabulary model keeps mistaking one desk for a table.
    rng = np.random.default_rng(zlib.crc32(fixture.id.encode("utf-8")))
    candidates = [label for label in FIXTURE_VOCABULARY if label != fixture.label]
    distractors = rng.choice(candidates, size=DISTRACTOR_COUNT, replace=False)
    distractor_scores = rng.uniform(*DISTRACTOR_SCORE_RANGE, size=DISTRACTOR_COUNT)
    scores = {fixture.label: TRUE_CLASS_SCORE}
    scores.update(
        (str(label), float(score))
        for label, score in zip(distractors, distractor_scores, strict=True)
    )
    return scores


def detect_fixtures(
    render: Render,
    world: World,
    rng: np.random.Generator,
    *,
    recall: float = 1.0,
    min_visible_pixels: int = 400,
    score_noise: float = 0.02,
    ambiguity: Mapping[str, Mapping[str, float]] | None = None,
) -> list[SimDetection]:
    """Fixture detections with noisy class scores; `ambiguity[id]` overrides scores per label."""
    visible_pixels = np.bincount(
        render.fixture_instance.ravel() + 1, minlength=len(world.fixtures) + 1
    )[1:]
    detections = []
    for index, fixture in enumerate(world.fixtures):
        if visible_pixels[index] < min_visible_pixels:
            continue
        # Same draw order as `detect`: recall first, then the kept fixture's noise, world order.
        if rng.random() >= recall:
            continue
        base_scores = fixture_class_scores(fixture)
        if ambiguity is not None:
            base_scores.update(ambiguity.get(fixture.id, {}))
        noise = rng.normal(0.0, score_noise, size=len(base_scores))
        noisy = np.clip(np.fromiter(base_scores.values(), dtype=np.float64) + noise, 0.0, 1.0)
        ranked = sorted(zip(base_scores, noisy.tolist(), strict=True), key=lambda pair: -pair[1])
        class_scores = dict(ranked)
        label, score = ranked[0]
        mask = render.fixture_instance == index
        detections.append(
            SimDetection(fixture.id, label, score, mask, None, "fixture", class_scores)
        )
    return detections
