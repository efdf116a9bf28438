"""The detector's channels that can fail the memory: each at its stated rate, each off at its kind
value (the old near-oracle behaviour), each field checked by name."""

from __future__ import annotations

import dataclasses
import functools
import math
import zlib

import numpy as np
import pytest

from sim import appearance_report
from sim.appearance import AppearanceModel, distinctiveness_of
from sim.appearance_report import GATE, measure, render
from sim.camera import CameraModel, look_at
from sim.detectability import DetectorLuck
from sim.detector import SimDetection
from sim.detector_model import RealisticDetector, support_of
from sim.detector_settings import AppearanceSpec, FixtureDetectorSpec
from sim.fixture_segmenter import (
    FixtureSegmenter,
    adjacent_pairs,
    ambiguity_of,
    fixture_luck_keys,
    footprint_gap,
)
from sim.masks import principal_angle
from sim.render import Render
from sim.render import render as render_view
from sim.scenario import REPO_ROOT, ScenarioError, load_scenario
from sim.spurious import SPURIOUS_FIXTURE_PREFIX, spurious_masks, spurious_sites
from sim.stream import simulate
from sim.world import Box, World

CAMERA = CameraModel()
SCENARIOS = REPO_ROOT / "sim" / "scenarios"
# Every fixture error at its kind value: one exact mask per visible fixture, true class on top.
KIND_FIELDS = (
    "recall",
    "score_noise",
    "partial_rate",
    "bleed_rate",
    "wrong_top_rate",
    "merge_rate",
    "split_rate",
    "spurious_per_m2",
)
KIND_FIXTURES = FixtureDetectorSpec(
    recall=1.0,
    score_noise=0.0,
    partial_rate=0.0,
    bleed_rate=0.0,
    wrong_top_rate=0.0,
    merge_rate=0.0,
    split_rate=0.0,
    spurious_per_m2=0.0,
)
OLD_APPEARANCE = AppearanceSpec(
    class_share=0.76,
    instance_share=0.08,
    view_share=0.10,
    context_share=0.0,
    distinctiveness=1.0,
    noise_spread=0.0,
)


def _fixture(name: str, label: str, center: tuple[float, float], size: tuple[float, ...]) -> Box:
    return Box(name, label, (*center, size[2] / 2), (size[0], size[1], size[2]), kind="fixture")


def _frames(
    segmenter: FixtureSegmenter, view: Render, world: World, count: int, seed: int = 0
) -> list[list[SimDetection]]:
    """The segmenter's detections over `count` frames of independent luck (no persistence)."""
    rng = np.random.default_rng(seed)
    keys = fixture_luck_keys(world.fixtures, segmenter.pairs, len(segmenter.sites))
    luck = DetectorLuck(keys, 0.0, rng)
    frames = []
    for _ in range(count):
        luck.step(rng)
        frames.append(list(segmenter.detect(view, world, rng, luck)))
    return frames


# -- appearance -------------------------------------------------------------------------------


def _unit(name: str, dim: int = 64) -> np.ndarray:
    vector = np.random.default_rng(zlib.crc32(name.encode())).standard_normal(dim)
    return np.asarray(vector / np.linalg.norm(vector))


def test_the_kind_appearance_setting_is_the_old_model() -> None:
    """Class 0.76, instance 0.08, view 0.10, the rest noise: the id-seeded vectors of before."""
    model = AppearanceModel(OLD_APPEARANCE, [("cup", "mug")])
    direction = np.array([0.6, 0.7, math.sqrt(1 - 0.85)])
    embedding = model.embed("mug_1", "mug", direction, np.random.default_rng(5))
    noise = np.random.default_rng(5).standard_normal(64)
    expected = (
        math.sqrt(0.76) * model.class_vector("mug")
        + math.sqrt(0.08) * _unit("appearance/instance/mug_1")
        + math.sqrt(0.10) * model.view_vector("mug_1", direction)
        + math.sqrt(0.06) * noise / np.linalg.norm(noise)
    )
    assert embedding is not None
    assert embedding == pytest.approx(expected / np.linalg.norm(expected), abs=1e-12)


def test_distinctiveness_has_the_knob_as_mean_and_keeps_each_look_rank() -> None:
    names = [f"mug_{index}" for index in range(3000)]
    for mean in (0.3, 0.5, 0.8):
        draws = np.array([distinctiveness_of(name, mean) for name in names])
        assert draws.mean() == pytest.approx(mean, abs=0.015)
        assert 0.1 < draws.std() < 0.3  # looks differ: some generic, some distinctive
    low = np.array([distinctiveness_of(name, 0.3) for name in names[:200]])
    high = np.array([distinctiveness_of(name, 0.8) for name in names[:200]])
    assert (np.argsort(low) == np.argsort(high)).all()  # a sweep moves every look the same way
    assert distinctiveness_of("mug_1", 1.0) == 1.0 and distinctiveness_of("mug_1", 0.0) == 0.0


def test_look_alike_objects_share_one_look_and_a_place_shares_its_context() -> None:
    # No noise share: two embeddings differ only by what the model puts in them.
    spec = dataclasses.replace(AppearanceSpec(), view_share=0.12, context_share=0.08)
    assert spec.noise_share == pytest.approx(0.0)
    alike = AppearanceModel(dataclasses.replace(spec, look_alike=(("mug_1", "mug_2"),)))
    apart = AppearanceModel(spec)
    direction = np.array([1.0, 0.0, 0.0])

    def embed(model: AppearanceModel, key: str, place: str) -> np.ndarray:
        embedding = model.embed(key, "mug", direction, np.random.default_rng(0), place=place)
        assert embedding is not None
        return embedding

    assert embed(alike, "mug_1", "desk") == pytest.approx(embed(alike, "mug_2", "desk"))
    assert float(embed(apart, "mug_1", "desk") @ embed(apart, "mug_2", "desk")) < 0.999
    # The same mug on another desk: only the context part differs (0.08 of the squared norm).
    moved = float(embed(apart, "mug_1", "desk") @ embed(apart, "mug_1", "shelf"))
    assert moved == pytest.approx(1 - 0.08, abs=0.03)


def test_the_report_shows_the_overlap_and_the_knob_moves_it() -> None:
    defaults = measure(AppearanceSpec(), trials=150)
    same = defaults.cosines["same instance"]
    other = defaults.cosines["same class, other instance"]
    assert 0.02 < (same < GATE).mean() < 0.15  # some views of one mug fall below the gate
    assert 0.25 < (other > GATE).mean() < 0.6  # some other mugs pass it
    assert (defaults.cosines["confusable class (mug-cup)"] > GATE).mean() < 0.03
    assert np.percentile(defaults.cosines["unrelated class (mug-book)"], 95) < 0.55
    right, wrong, undecided = defaults.choices["look-alike mugs, carried"]
    assert wrong > right and right + wrong + undecided == 150  # alike mugs: the place decides
    distinct = measure(dataclasses.replace(AppearanceSpec(), distinctiveness=1.0), trials=50)
    generic = measure(dataclasses.replace(AppearanceSpec(), distinctiveness=0.2), trials=50)
    above = {
        name: (figures.cosines["same class, other instance"] > GATE).mean()
        for name, figures in (("distinct", distinct), ("generic", generic))
    }
    assert above["distinct"] < 0.15 < 0.6 < above["generic"]
    lines = render(defaults, "defaults:")
    assert lines[0] == "defaults:" and any("right" in line and "wrong" in line for line in lines)


def test_the_report_command_prints_the_defaults_and_each_knob_value(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    quick = functools.partial(measure, trials=20)
    monkeypatch.setattr(appearance_report, "measure", quick)
    appearance_report.main(["--distinctiveness", "0.3"])
    printed = capsys.readouterr().out
    assert "defaults:" in printed and "distinctiveness 0.3:" in printed
    assert printed.count("same instance") == 2 and printed.count(" right ") == 2 * 4


def test_an_object_crop_shows_its_support() -> None:
    desk = _fixture("desk_1", "desk", (2.0, 2.0), (1.4, 0.7, 0.75))
    mug = Box("mug_1", "mug", (2.3, 2.1, 0.80), (0.08, 0.08, 0.10))
    assert support_of(mug, [desk]) == "desk_1"
    assert support_of(dataclasses.replace(mug, center=(3.0, 2.1, 0.80)), [desk]) == "floor"


# -- class scores -----------------------------------------------------------------------------


def _confused_scores(keeps_truth: float, draws: int = 4000) -> list[dict[str, float] | None]:
    labels = {"confusable": [["cup", "mug"], ["book", "magazine"]], "confusion_keeps_truth": 0}
    labels["confusion_keeps_truth"] = keeps_truth
    scenario = load_scenario(SCENARIOS / "hotel-suite.yaml", {"detector": {"labels": labels}})
    rng = np.random.default_rng(3)
    detector = RealisticDetector(scenario, rng)
    return [detector.class_scores("mug", "book", rng) for _ in range(draws)]


def test_a_confused_label_keeps_the_true_group_at_its_stated_rate() -> None:
    scores = _confused_scores(0.25)
    kept = [s for s in scores if s is not None and "mug" in s]
    assert len(kept) / len(scores) == pytest.approx(0.25, abs=0.03)
    wrong = [s for s in scores if s is not None and "mug" not in s]
    # Confidently wrong: the reported class's own group, nothing of the true one.
    assert wrong and all(set(s) == {"book", "magazine"} and next(iter(s)) == "book" for s in wrong)
    # The kind value: every confused label carries its true group, as before.
    assert all(s is not None and {"mug", "cup"} <= set(s) for s in _confused_scores(1.0, 300))


# -- fixtures ---------------------------------------------------------------------------------


def test_each_fixture_reads_wrong_in_its_own_share_of_views() -> None:
    fixtures = tuple(
        _fixture(f"table_{i}", "table", (0.9 + 1.1 * i, 3.0), (0.8, 0.6, 0.75)) for i in range(4)
    )
    world = World((5.0, 5.0, 2.6), fixtures, ())
    view = render_view(world, CAMERA, look_at((2.5, 0.4, 1.5), (2.5, 3.0, 0.5)))
    spec = dataclasses.replace(KIND_FIXTURES, wrong_top_rate=0.25, score_noise=0.04)
    frames = _frames(FixtureSegmenter(spec, [], fixtures), view, world, 600)
    for fixture in fixtures:
        seen = [d for frame in frames for d in frame if d.object_id == fixture.id]
        wrong = np.mean([d.label == "desk" for d in seen])
        assert len(seen) == 600
        assert wrong == pytest.approx(ambiguity_of(fixture.id, 0.25, 5.0), abs=0.06)
    rates = [ambiguity_of(f"table_{i}", 0.25, 5.0) for i in range(400)]
    assert np.mean(rates) == pytest.approx(0.25, abs=0.02) and np.std(rates) > 0.1
    # Concentration 0: every fixture reads wrong in the same share of views, as before.
    flat = dataclasses.replace(spec, ambiguity_concentration=0.0, wrong_top_rate=0.08)
    frames = _frames(FixtureSegmenter(flat, [], fixtures), view, world, 600, seed=1)
    tops = [d.label for frame in frames for d in frame]
    assert np.mean([label == "desk" for label in tops]) == pytest.approx(0.08, abs=0.02)
    assert {ambiguity_of(f.id, 0.08, 0.0) for f in fixtures} == {0.08}


def test_adjacent_fixtures_are_merged_in_their_share_of_views() -> None:
    bed = _fixture("bed_1", "bed", (2.0, 3.0), (1.6, 2.0, 0.55))
    nightstand = _fixture("nightstand_1", "cabinet", (3.05, 3.8), (0.45, 0.4, 0.55))
    shelf = _fixture("shelf_1", "shelf", (4.4, 1.0), (0.5, 1.0, 1.6))  # too far and too tall
    assert footprint_gap(bed, nightstand) == pytest.approx(0.025, abs=1e-9)
    assert footprint_gap(bed, shelf) > 1.0
    assert adjacent_pairs((bed, nightstand, shelf), 0.2) == [("bed_1", "nightstand_1")]
    world = World((5.0, 5.0, 2.6), (bed, nightstand, shelf), ())
    view = render_view(world, CAMERA, look_at((2.5, 0.3, 1.5), (2.5, 3.2, 0.3)))
    exact = {f.id: view.fixture_instance == i for i, f in enumerate(world.fixtures)}
    spec = dataclasses.replace(KIND_FIXTURES, merge_rate=0.4)
    frames = _frames(FixtureSegmenter(spec, [], world.fixtures), view, world, 500)
    merged = 0
    for frame in frames:
        ids = [d.object_id for d in frame]
        if "nightstand_1" not in ids:
            merged += 1
            union = next(d.mask for d in frame if d.object_id == "bed_1")
            assert (union == (exact["bed_1"] | exact["nightstand_1"])).all()
    assert merged / len(frames) == pytest.approx(0.4, abs=0.07)
    kind = _frames(FixtureSegmenter(KIND_FIXTURES, [], world.fixtures), view, world, 50)
    shown = {f.id for f in world.fixtures if exact[f.id].sum() >= KIND_FIXTURES.min_visible_pixels}
    assert {"bed_1", "nightstand_1"} <= shown
    assert all(sorted(d.object_id for d in frame) == sorted(shown) for frame in kind)


def test_a_long_fixture_is_split_in_its_share_of_views() -> None:
    table = _fixture("table_1", "table", (2.5, 3.0), (2.2, 0.9, 0.75))
    stand = _fixture("stand_1", "cabinet", (0.8, 1.5), (0.5, 0.5, 0.6))  # short: never split
    world = World((5.0, 5.0, 2.6), (table, stand), ())
    view = render_view(world, CAMERA, look_at((2.5, 0.2, 1.5), (2.0, 2.5, 0.4)))
    exact = view.fixture_instance == 0
    spec = dataclasses.replace(KIND_FIXTURES, split_rate=0.3)
    frames = _frames(FixtureSegmenter(spec, [], world.fixtures), view, world, 500)
    split = 0
    for frame in frames:
        halves = [d.mask for d in frame if d.object_id == "table_1"]
        assert sum(d.object_id == "stand_1" for d in frame) == 1
        if len(halves) == 2:
            split += 1
            assert not (halves[0] & halves[1]).any() and ((halves[0] | halves[1]) == exact).all()
    assert split / len(frames) == pytest.approx(0.3, abs=0.06)
    wide = np.zeros((40, 100), dtype=bool)
    wide[10:20, 10:90] = True
    assert principal_angle(wide) == pytest.approx(0.0, abs=1e-6)
    assert abs(principal_angle(wide.T)) == pytest.approx(math.pi / 2, abs=1e-6)


def test_spurious_sites_come_at_their_density_and_lie_on_their_surfaces() -> None:
    chair = Box("chair_1", "chair", (4.0, 4.0, 0.45), (0.5, 0.5, 0.9), kind="occluder")
    counts, kinds = [], set()
    for seed in range(300):
        sites = spurious_sites((6.0, 5.0, 2.6), [], [chair], 0.1, np.random.default_rng(seed))
        counts.append(len(sites))
        kinds |= {site.kind for site in sites}
    assert np.mean(counts) == pytest.approx(3.0, abs=0.25)  # Poisson(0.1 / m2 x 30 m2)
    assert kinds == {"wall", "floor", "low"}
    assert spurious_sites((6.0, 5.0, 2.6), [], [chair], 0.0, np.random.default_rng(0)) == []
    sites = spurious_sites((6.0, 5.0, 2.6), [], [chair], 0.5, np.random.default_rng(1))
    world = World((6.0, 5.0, 2.6), (), (), occluders=(chair,))
    checked = set()
    for eye, target in (((3.0, 2.5, 1.3), (0.0, 2.5, 0.6)), ((3.0, 2.5, 1.3), (6.0, 2.5, 0.6))):
        view = render_view(world, CAMERA, look_at(eye, target))
        for site, mask in spurious_masks(sites, view, world, 400):
            checked.add(site.kind)
            assert site.id.startswith(SPURIOUS_FIXTURE_PREFIX)
            if site.region is not None:
                rows, cols = np.nonzero(mask)
                depth = view.depth[rows, cols]
                rays = np.stack(
                    [
                        (cols - CAMERA.cx) / CAMERA.fx,
                        (rows - CAMERA.cy) / CAMERA.fy,
                        np.ones_like(depth),
                    ]
                )
                points = (view.pose[:3, :3] @ (rays * depth)).T + view.pose[:3, 3]
                low = np.subtract(site.region.center, np.divide(site.region.size, 2)) - 1e-6
                high = np.add(site.region.center, np.divide(site.region.size, 2)) + 1e-6
                assert ((points >= low) & (points <= high)).all()
    assert "wall" in checked or "floor" in checked


def test_a_site_in_view_is_reported_in_its_share_of_views() -> None:
    world = World((6.0, 5.0, 2.6), (), ())
    sites = spurious_sites((6.0, 5.0, 2.6), [], [], 0.15, np.random.default_rng(4))
    view = render_view(world, CAMERA, look_at((3.0, 2.5, 1.6), (3.0, 0.0, 0.4)))
    in_view = {site.id for site, _ in spurious_masks(sites, view, world, 400)}
    assert in_view
    spec = dataclasses.replace(KIND_FIXTURES, spurious_recall=0.3)
    frames = _frames(FixtureSegmenter(spec, [], (), sites), view, world, 300)
    reported = [d for frame in frames for d in frame]
    assert {d.object_id for d in reported} == in_view
    share = len(reported) / (len(frames) * len(in_view))
    assert share == pytest.approx(0.3, abs=0.06)
    assert all(d.kind == "fixture" and d.class_scores for d in reported)


def test_the_kind_fixture_setting_gives_one_exact_mask_per_fixture_with_its_class_on_top() -> None:
    kind = {name: getattr(KIND_FIXTURES, name) for name in KIND_FIELDS}
    scenario = load_scenario(
        SCENARIOS / "bedroom.yaml", {"detector": {"fixtures": kind}}, frames=12
    )
    run = simulate(scenario, seed=2)
    seen = 0
    for frame in run.frames:
        fixtures = [d for d in frame.detections if d.kind == "fixture"]
        assert len({d.object_id for d in fixtures}) == len(fixtures)  # no split, no merge
        for detection in fixtures:
            assert not detection.object_id.startswith(SPURIOUS_FIXTURE_PREFIX)
            assert detection.label == scenario.fixture(detection.object_id).label
            seen += 1
    assert seen >= 12


@pytest.mark.parametrize(
    ("detector", "field"),
    [
        ({"appearance": {"distinctiveness": 1.5}}, r"detector\.appearance\.distinctiveness"),
        ({"appearance": {"noise_spread": 3}}, r"detector\.appearance\.noise_spread"),
        ({"appearance": {"context_share": 0.3}}, r"detector\.appearance\.context_share"),
        ({"appearance": {"look_alike": [["cup_1"]]}}, r"detector\.appearance\.look_alike\[0\]"),
        ({"appearance": {"look_alike": [["mug_1", "ghost"]]}}, r"look_alike\[0\]: unknown object 'ghost'"),
        ({"labels": {"confusion_keeps_truth": -0.1}}, r"detector\.labels\.confusion_keeps_truth"),
        ({"fixtures": {"merge_rate": 2}}, r"detector\.fixtures\.merge_rate"),
        ({"fixtures": {"merge_gap_m": -1}}, r"detector\.fixtures\.merge_gap_m"),
        ({"fixtures": {"split_rate": 1.1}}, r"detector\.fixtures\.split_rate"),
        ({"fixtures": {"split_min_length_m": 0}}, r"detector\.fixtures\.split_min_length_m"),
        ({"fixtures": {"spurious_per_m2": -0.1}}, r"detector\.fixtures\.spurious_per_m2"),
        ({"fixtures": {"spurious_recall": 1.5}}, r"detector\.fixtures\.spurious_recall"),
        ({"fixtures": {"ambiguity_concentration": -1}}, r"detector\.fixtures\.ambiguity_concentration"),
    ],
)  # fmt: skip
def test_a_bad_channel_field_is_named(detector: dict[str, object], field: str) -> None:
    with pytest.raises(ScenarioError, match=field):
        load_scenario(SCENARIOS / "hotel-suite.yaml", {"detector": detector})
