"""Oracle detector: visibility threshold, recall, embeddings and mask leakage."""

from __future__ import annotations

import numpy as np

from bench.sim.camera import CameraModel
from bench.sim.detector import detect, object_embedding
from bench.sim.render import Render
from bench.sim.world import Box, World

CAMERA = CameraModel(width=80, height=60)
WORLD = World(
    room_size=(4.0, 4.0, 2.5),
    fixtures=(Box("table", "table", (2.0, 2.0, 0.4), (1.0, 1.0, 0.8), kind="fixture"),),
    objects=(
        Box("mug", "mug", (2.0, 2.0, 0.85), (0.1, 0.1, 0.1)),
        Box("book", "book", (2.2, 2.0, 0.82), (0.2, 0.15, 0.04)),
    ),
)


def painted_render(mug_pixels: tuple[slice, slice], book_pixels: tuple[slice, slice]) -> Render:
    """A Render with hand-painted instance rectangles, so pixel counts are known exactly."""
    instance = np.full((CAMERA.height, CAMERA.width), -1, dtype=np.int32)
    instance[mug_pixels] = 0
    instance[book_pixels] = 1
    fixture_instance = np.where(instance == -1, 0, -1).astype(np.int32)
    depth = np.ones((CAMERA.height, CAMERA.width), dtype=np.float32)
    return Render(depth, instance, fixture_instance, CAMERA, np.eye(4))


MUG_RECT = (slice(10, 20), slice(10, 30))  # 200 pixels
BOOK_RECT = (slice(30, 40), slice(40, 50))  # 100 pixels
VIEW = painted_render(MUG_RECT, BOOK_RECT)


def test_min_visible_pixels_is_an_inclusive_threshold() -> None:
    rng = np.random.default_rng(0)
    assert [d.object_id for d in detect(VIEW, WORLD, rng, min_visible_pixels=100)] == [
        "mug",
        "book",
    ]
    assert [d.object_id for d in detect(VIEW, WORLD, rng, min_visible_pixels=101)] == ["mug"]
    assert detect(VIEW, WORLD, rng, min_visible_pixels=201) == []


def test_detections_carry_label_score_and_exact_mask() -> None:
    (mug,) = detect(VIEW, WORLD, np.random.default_rng(0), score=0.77)
    assert (mug.label, mug.score, mug.kind) == ("mug", 0.77, "object")
    assert mug.mask.dtype == bool and mug.mask.sum() == 200 and mug.mask[MUG_RECT].all()


def test_recall_keeps_about_that_fraction() -> None:
    rng = np.random.default_rng(5)
    kept = sum(len(detect(VIEW, WORLD, rng, recall=0.6, min_visible_pixels=50)) for _ in range(500))
    assert abs(kept / 1000 - 0.6) < 0.05
    assert detect(VIEW, WORLD, rng, recall=0.0, min_visible_pixels=50) == []


def test_same_seed_gives_same_detections() -> None:
    def run(seed: int) -> list[tuple[str, float]]:
        found = detect(VIEW, WORLD, np.random.default_rng(seed), recall=0.5, embedding_noise=0.1)
        return [(d.object_id, float(d.embedding[0])) for d in found]

    assert run(9) == run(9)


def test_fixtures_are_never_detected() -> None:
    empty = painted_render((slice(0, 0), slice(0, 0)), (slice(0, 0), slice(0, 0)))
    assert (empty.fixture_instance == 0).sum() > 150
    assert detect(empty, WORLD, np.random.default_rng(0), min_visible_pixels=1) == []


def test_object_embedding_is_stable_unit_and_distinct() -> None:
    mug = object_embedding("mug")
    assert mug.shape == (64,) and mug.dtype == np.float64
    assert np.array_equal(mug, object_embedding("mug"))
    assert abs(np.linalg.norm(mug) - 1.0) < 1e-12
    names = ["mug", "book", "bowl", "bottle", "mug-2", "table"]
    vectors = np.stack([object_embedding(name) for name in names])
    cosines = vectors @ vectors.T
    assert np.abs(cosines[~np.eye(len(names), dtype=bool)]).max() < 0.5
    mug[0] = 99.0  # callers get copies, so the cache cannot be corrupted
    assert object_embedding("mug")[0] != 99.0


def test_detector_embedding_is_noisy_and_not_renormalised() -> None:
    rng = np.random.default_rng(1)
    (clean,) = detect(VIEW, WORLD, rng)
    assert np.array_equal(clean.embedding, object_embedding("mug"))
    (noisy,) = detect(VIEW, WORLD, rng, embedding_noise=0.05)
    difference = noisy.embedding - object_embedding("mug")
    assert 0.03 < float(np.std(difference)) < 0.07
    assert abs(np.linalg.norm(noisy.embedding) - 1.0) > 1e-6
    (bare,) = detect(VIEW, WORLD, rng, embedding_dim=None)
    assert bare.embedding is None


def test_boundary_leak_grows_the_mask_onto_background() -> None:
    rng = np.random.default_rng(0)
    (tight,) = detect(VIEW, WORLD, rng, boundary_leak_px=0)
    (leaky,) = detect(VIEW, WORLD, rng, boundary_leak_px=2)
    assert (leaky.mask >= tight.mask).all()
    assert leaky.mask.sum() == (10 + 4) * (20 + 4)  # the 10x20 rectangle grows 2 px each side
    assert leaky.mask[8, 8] and not leaky.mask[7, 10]
