"""The `detector:` section of a scenario: every error mode of the simulated detector, each a setting.

The defaults are the realistic detector (`sim/scenarios/README.md` gives the figures and the
reasons); a scenario only writes what is particular to its world (confusable classes, phantoms,
look-alike objects). Setting each mode to its kind value (recall 1.0, rates 0,
`confusion_keeps_truth: 1`, `spurious_per_m2: 0`) gives back the near-oracle detector of the
first evaluation; the README's "Oracle" paragraph lists them, the appearance model of before too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sim.scenario_fields import (
    ScenarioError,
    Section,
    count,
    fraction,
    number,
    positive,
    sequence,
    text,
    vector,
)

DEPTH_NOISE_MODELS = ("kinect", "none")


@dataclass(frozen=True)
class RecallSpec:
    """How likely a visible object is reported, from its view; misses persist over time.

    `viewpoint: False` is the flat model: every detectable object is reported with probability
    `peak`, independently per frame (a bare number in the file means that).
    """

    peak: float = 0.90  # the best case: near, large, frontal, whole, inside the image
    half_area_px: float = 400.0  # mask area at which area alone halves recall
    half_distance_m: float = 4.5  # distance at which range alone halves recall
    grazing_deg: tuple[float, float] = (5.0, 25.0)  # recall ramps up between these view angles
    truncation_zero: float = 0.8  # recall reaches 0 when this share lies outside the image
    visible_fraction: tuple[float, float] = (
        0.15,
        0.7,
    )  # occlusion ramp: 0 at first, full at second
    miss_correlation_s: float = 1.0  # correlation time of the detector's luck (0: independent)
    viewpoint: bool = True


@dataclass(frozen=True)
class MaskSpec:
    """How object masks differ from the true visible silhouette."""

    boundary_leak_px: int = 1  # every mask grows this much onto whatever is behind
    partial_rate: float = 0.15  # share of masks covering only part of the object
    partial_keep: tuple[float, float] = (0.45, 0.85)  # the part kept, drawn uniformly
    split_rate: float = 0.05  # share of objects reported as two detections (over-segmented)
    support_bleed_rate: float = 0.25  # share of masks that spill onto the supporting surface
    support_bleed_px: tuple[int, int] = (3, 10)  # how far they spill, drawn uniformly


@dataclass(frozen=True)
class LabelSpec:
    """Which classes the detector mixes up, and how often."""

    confusable: tuple[tuple[str, ...], ...] = ()  # groups of classes mistaken for one another
    flicker: float = 0.15  # per detection: another class of its confusable group
    confusion: float = 0.01  # per detection: any other object class of the scenario
    # Share of those confusions whose class scores still carry the true class's group (the
    # rest score the reported class's own group: confidently wrong).
    confusion_keeps_truth: float = 0.25


@dataclass(frozen=True)
class AppearanceSpec:
    """A CLIP-like appearance vector: shares of the squared norm (the rest is per-view noise)."""

    dim: int | None = 64  # None: the detector sends no embedding
    class_share: float = 0.70  # common to every instance of a class
    instance_share: float = 0.10  # this instance's look (a share of it its own, see below)
    view_share: float = 0.09  # varies smoothly with the direction the object is seen from
    context_share: float = 0.04  # what a crop shows around the object: common to one place
    shared_share: float = 0.50  # of a class vector: common to every class (CLIP's narrow cone)
    group_share: float = 0.35  # of a class vector: common to its confusable group
    # Mean share of an instance part that is the look's own (the rest looks like its class):
    # the overlap knob between one instance and another of its class (1: every look distinct).
    distinctiveness: float = 0.5
    noise_spread: float = 1.0  # log-normal spread of a detection's noise share (0: fixed)
    look_alike: tuple[tuple[str, ...], ...] = ()  # groups of object ids that look the same

    @property
    def noise_share(self) -> float:
        """What is left for per-detection noise (crop, blur, mask errors)."""
        shares = self.class_share + self.instance_share + self.view_share + self.context_share
        return max(0.0, 1.0 - shares)


@dataclass(frozen=True)
class PhantomSpec:
    """A persistent false positive: a flat picture (poster, reflection) read as an object."""

    id: str
    label: str
    at: tuple[float, float, float]  # center of the picture, world frame
    size: tuple[float, float]  # width along the wall, height
    facing: float  # yaw [rad] of the picture's normal (the side it is seen from)
    cone_deg: float = 50.0  # seen as an object only within this angle of its normal
    recall: float = 0.7  # how convincing it is: scales the viewpoint recall


@dataclass(frozen=True)
class FixtureDetectorSpec:
    """The open-vocabulary fixture segmenter (see `sim.fixture_segmenter`)."""

    recall: float = 0.9
    score_noise: float = 0.04
    min_visible_pixels: int = 400
    ambiguity: Mapping[str, Mapping[str, float]] | None = None
    partial_rate: float = 0.3  # share of masks covering only part of the fixture
    partial_keep: tuple[float, float] = (0.5, 0.9)
    bleed_rate: float = 0.2  # share of masks spilling into an adjacent fixture
    bleed_px: tuple[int, int] = (4, 12)
    wrong_top_rate: float = 0.10  # mean share of views whose top class is a wrong one
    ambiguity_concentration: float = 5.0  # Beta concentration of that share per fixture (0: none)
    merge_rate: float = 0.15  # share of views of two adjacent fixtures segmented as one mask
    merge_gap_m: float = 0.20  # adjacent: footprints at most this far apart, tops level
    split_rate: float = 0.10  # share of views of a long fixture segmented as two halves
    split_min_length_m: float = 1.6  # long: a footprint side at least this long
    spurious_per_m2: float = 0.05  # hallucination sites per square metre of floor
    spurious_recall: float = 0.30  # share of views in which a site in view is reported


@dataclass(frozen=True)
class DetectorSpec:
    """The simulated detector's error modes and the depth noise model."""

    min_visible_pixels: int = 150  # the smallest mask reported (at 640 x 480)
    # Rollouts only: the detector run on the keyframes the robot posts while it moves sees the
    # frame downsampled by this factor per axis (an object's pixel area counts scale^2 against
    # `min_visible_pixels` and the area recall); inspection captures run at full resolution.
    far_range_input_scale: float = 0.5
    recall: RecallSpec = field(default_factory=RecallSpec)
    masks: MaskSpec = field(default_factory=MaskSpec)
    labels: LabelSpec = field(default_factory=LabelSpec)
    appearance: AppearanceSpec = field(default_factory=AppearanceSpec)
    false_positives_per_frame: float = 0.05
    phantoms: tuple[PhantomSpec, ...] = ()
    score: float = 0.9
    depth_noise: str = "kinect"
    fixtures: FixtureDetectorSpec | None = field(default_factory=FixtureDetectorSpec)

    @property
    def embedding_dim(self) -> int | None:
        """Size of the appearance vector (None: no embeddings)."""
        return self.appearance.dim


def _ordered_pair(value: Any, where: str, parse: Any = number) -> tuple[Any, Any]:
    """[low, high] with low <= high."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ScenarioError(f"{where}: expected [low, high], got {value!r}")
    low, high = parse(value[0], f"{where}[0]"), parse(value[1], f"{where}[1]")
    if low > high:
        raise ScenarioError(f"{where}: low {low} exceeds high {high}")
    return low, high


def _fraction_pair(value: Any, where: str) -> tuple[float, float]:
    return _ordered_pair(value, where, fraction)


def _pixel_pair(value: Any, where: str) -> tuple[int, int]:
    return _ordered_pair(value, where, count)


def _non_negative(value: Any, where: str) -> float:
    return positive(value, where, zero=True)


def _recall(value: Any, where: str) -> RecallSpec:
    """`recall`: a number (flat, independent per frame) or the viewpoint model's mapping."""
    if not isinstance(value, Mapping):
        return RecallSpec(peak=fraction(value, where), miss_correlation_s=0.0, viewpoint=False)
    section, default = Section(value, where), RecallSpec()
    spec = RecallSpec(
        peak=section.get("peak", fraction, default.peak),
        half_area_px=section.get("half_area_px", _non_negative, default.half_area_px),
        half_distance_m=section.get("half_distance_m", positive, default.half_distance_m),
        grazing_deg=section.get(
            "grazing_deg",
            lambda item, at: _ordered_pair(item, at, lambda v, w: number(v, w, 0.0, 90.0)),
            default.grazing_deg,
        ),
        truncation_zero=section.get(
            "truncation_zero", lambda item, at: number(item, at, 0.01, 1.0), default.truncation_zero
        ),
        visible_fraction=section.get("visible_fraction", _fraction_pair, default.visible_fraction),
        miss_correlation_s=section.get(
            "miss_correlation_s", _non_negative, default.miss_correlation_s
        ),
    )
    section.finish()
    return spec


def _masks(value: Any, where: str) -> MaskSpec:
    section, default = Section(value, where), MaskSpec()
    spec = MaskSpec(
        boundary_leak_px=section.get("boundary_leak_px", count, default.boundary_leak_px),
        partial_rate=section.get("partial_rate", fraction, default.partial_rate),
        partial_keep=section.get("partial_keep", _fraction_pair, default.partial_keep),
        split_rate=section.get("split_rate", fraction, default.split_rate),
        support_bleed_rate=section.get("support_bleed_rate", fraction, default.support_bleed_rate),
        support_bleed_px=section.get("support_bleed_px", _pixel_pair, default.support_bleed_px),
    )
    section.finish()
    return spec


def _disjoint_groups(value: Any, where: str, noun: str) -> tuple[tuple[str, ...], ...]:
    """Groups of two or more distinct names, no name in two groups (confusable classes, looks)."""

    def group(item: Any, at: str) -> tuple[str, ...]:
        names = tuple(sequence(item, at, text))
        if len(names) < 2 or len(set(names)) != len(names):
            raise ScenarioError(f"{at}: a group needs two or more distinct {noun}")
        return names

    groups = tuple(sequence(value, where, group))
    seen: dict[str, int] = {}
    for index, members in enumerate(groups):
        for name in members:
            if name in seen:
                raise ScenarioError(f"{where}[{index}]: {name!r} is already in group {seen[name]}")
            seen[name] = index
    return groups


def _labels(value: Any, where: str) -> LabelSpec:
    section, default = Section(value, where), LabelSpec()
    spec = LabelSpec(
        confusable=section.get(
            "confusable", lambda item, at: _disjoint_groups(item, at, "classes"), ()
        ),
        flicker=section.get("flicker", fraction, default.flicker),
        confusion=section.get("confusion", fraction, default.confusion),
        confusion_keeps_truth=section.get(
            "confusion_keeps_truth", fraction, default.confusion_keeps_truth
        ),
    )
    section.finish()
    return spec


def _appearance(value: Any, where: str) -> AppearanceSpec:
    section, default = Section(value, where), AppearanceSpec()
    dim_given = "dim" in section.data
    dim = section.get("dim", lambda item, at: int(positive(item, at, integer=True)), None)
    spec = AppearanceSpec(
        dim=dim if dim_given else default.dim,
        class_share=section.get("class_share", fraction, default.class_share),
        instance_share=section.get("instance_share", fraction, default.instance_share),
        view_share=section.get("view_share", fraction, default.view_share),
        context_share=section.get("context_share", fraction, default.context_share),
        shared_share=section.get("shared_share", fraction, default.shared_share),
        group_share=section.get("group_share", fraction, default.group_share),
        distinctiveness=section.get("distinctiveness", fraction, default.distinctiveness),
        noise_spread=section.get(
            "noise_spread", lambda item, at: number(item, at, 0.0, 2.0), default.noise_spread
        ),
        look_alike=section.get(
            "look_alike", lambda item, at: _disjoint_groups(item, at, "object ids"), ()
        ),
    )
    section.finish()
    if spec.class_share + spec.instance_share + spec.view_share + spec.context_share > 1 + 1e-9:
        raise ScenarioError(
            f"{where}.context_share: class, instance, view and context shares exceed 1"
        )
    if spec.shared_share + spec.group_share > 1.0 + 1e-9:
        raise ScenarioError(f"{where}.group_share: shared and group shares exceed 1")
    return spec


def _phantom(value: Any, where: str) -> PhantomSpec:
    section, default = Section(value, where), PhantomSpec("", "", (0, 0, 0), (1, 1), 0.0)
    spec = PhantomSpec(
        id=section.get("id", text),
        label=section.get("label", text),
        at=section.get("at", lambda item, at: vector(item, at, 3)),
        size=section.get("size", lambda item, at: vector(item, at, 2, positive_only=True)),
        facing=section.get("facing", number),
        cone_deg=section.get(
            "cone_deg", lambda item, at: number(item, at, 1.0, 90.0), default.cone_deg
        ),
        recall=section.get("recall", fraction, default.recall),
    )
    section.finish()
    return spec


def _ambiguity(value: Any, where: str) -> dict[str, dict[str, float]]:
    """Fixture id -> {label: score} overrides."""
    section = Section(value, where)
    parsed = {}
    for fixture_id in map(str, value):
        scores = section.get(fixture_id, lambda item, at: Section(item, at).data)
        parsed[fixture_id] = {
            str(label): fraction(score, f"{where}.{fixture_id}.{label}")
            for label, score in scores.items()
        }
    return parsed


def _fixture_detector(value: Any, where: str) -> FixtureDetectorSpec:
    """The `detector.fixtures` section."""
    section, default = Section(value, where), FixtureDetectorSpec()
    spec = FixtureDetectorSpec(
        recall=section.get("recall", fraction, default.recall),
        score_noise=section.get("score_noise", _non_negative, default.score_noise),
        min_visible_pixels=section.get("min_visible_pixels", count, default.min_visible_pixels),
        ambiguity=section.get("ambiguity", _ambiguity, None),
        partial_rate=section.get("partial_rate", fraction, default.partial_rate),
        partial_keep=section.get("partial_keep", _fraction_pair, default.partial_keep),
        bleed_rate=section.get("bleed_rate", fraction, default.bleed_rate),
        bleed_px=section.get("bleed_px", _pixel_pair, default.bleed_px),
        wrong_top_rate=section.get("wrong_top_rate", fraction, default.wrong_top_rate),
        ambiguity_concentration=section.get(
            "ambiguity_concentration",
            lambda item, at: number(item, at, 0.0, 1000.0),
            default.ambiguity_concentration,
        ),
        merge_rate=section.get("merge_rate", fraction, default.merge_rate),
        merge_gap_m=section.get(
            "merge_gap_m", lambda item, at: number(item, at, 0.0, 2.0), default.merge_gap_m
        ),
        split_rate=section.get("split_rate", fraction, default.split_rate),
        split_min_length_m=section.get("split_min_length_m", positive, default.split_min_length_m),
        spurious_per_m2=section.get(
            "spurious_per_m2", lambda item, at: number(item, at, 0.0, 1.0), default.spurious_per_m2
        ),
        spurious_recall=section.get("spurious_recall", fraction, default.spurious_recall),
    )
    section.finish()
    return spec


def parse_detector(value: Any, where: str) -> DetectorSpec:
    """The `detector` section (every field optional; the defaults are the realistic detector)."""
    section, default = Section(value, where), DetectorSpec()
    noise_model = section.get("depth_noise", text, default.depth_noise)
    if noise_model not in DEPTH_NOISE_MODELS:
        raise ScenarioError(f"{where}.depth_noise: {noise_model!r} is not one of kinect, none")
    fixtures_given = section.data.get("fixtures", {}) is not None  # explicit null turns them off
    fixtures = section.get("fixtures", _fixture_detector, FixtureDetectorSpec())
    phantoms = tuple(section.get("phantoms", lambda item, at: sequence(item, at, _phantom), []))
    spec = DetectorSpec(
        min_visible_pixels=section.get("min_visible_pixels", count, default.min_visible_pixels),
        far_range_input_scale=section.get(
            "far_range_input_scale",
            lambda item, at: number(item, at, 0.05, 1.0),
            default.far_range_input_scale,
        ),
        recall=section.get("recall", _recall, RecallSpec()),
        masks=section.get("masks", _masks, MaskSpec()),
        labels=section.get("labels", _labels, LabelSpec()),
        appearance=section.get("appearance", _appearance, AppearanceSpec()),
        false_positives_per_frame=section.get(
            "false_positives_per_frame", _non_negative, default.false_positives_per_frame
        ),
        phantoms=phantoms,
        score=section.get("score", fraction, default.score),
        depth_noise=noise_model,
        fixtures=fixtures if fixtures_given else None,
    )
    section.finish()
    ids = [phantom.id for phantom in phantoms]
    for index, phantom_id in enumerate(ids):
        if phantom_id in ids[:index]:
            raise ScenarioError(f"{where}.phantoms[{index}].id: {phantom_id!r} is used twice")
    return spec


def correlation_per_frame(correlation_s: float, frame_period: float) -> float:
    """AR(1) coefficient between consecutive frames for a correlation time (0 s: independent)."""
    return 0.0 if correlation_s <= 0 else math.exp(-frame_period / correlation_s)
