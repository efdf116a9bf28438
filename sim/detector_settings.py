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
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, Field

from sim.scenario_fields import (
    CHECKED,
    Count,
    CountPair,
    Flag,
    Fraction,
    FractionPair,
    NonNegative,
    Number,
    Positive,
    PositiveInt,
    Text,
    Vec3,
    field_error,
    ordered,
)


def _flat_recall(value: Any) -> Any:
    """A bare number is the flat model: that recall, independent per frame."""
    if isinstance(value, dict) and "viewpoint" in value:
        raise field_error("viewpoint", "unknown field (a bare number gives the flat model)")
    if isinstance(value, dict):
        return value
    return {"peak": value, "miss_correlation_s": 0.0, "viewpoint": False}


def _distinct(names: tuple[str, ...]) -> tuple[str, ...]:
    if len(set(names)) != len(names):
        raise ValueError(f"a group needs two or more distinct names, got {list(names)}")
    return names


def _disjoint(groups: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], ...]:
    seen: dict[str, int] = {}
    for index, members in enumerate(groups):
        for name in members:
            if name in seen:
                raise field_error(f"[{index}]", f"{name!r} is already in group {seen[name]}")
            seen[name] = index
    return groups


# Groups of two or more distinct names, no name in two groups (confusable classes, looks).
Groups = Annotated[
    tuple[Annotated[tuple[Text, ...], Field(min_length=2), AfterValidator(_distinct)], ...],
    AfterValidator(_disjoint),
]


@dataclass(frozen=True)
class RecallSpec:
    """How likely a visible object is reported, from its view; misses persist over time.

    `viewpoint: False` is the flat model: every detectable object is reported with probability
    `peak`, independently per frame (a bare number in the file means that).
    """

    __pydantic_config__ = CHECKED
    peak: Fraction = 0.90  # the best case: near, large, frontal, whole, inside the image
    half_area_px: NonNegative = 400.0  # mask area at which area alone halves recall
    half_distance_m: Positive = 4.5  # distance at which range alone halves recall
    # Recall ramps up between these view angles (from the surface, so at most 90 degrees).
    grazing_deg: Annotated[
        tuple[Annotated[Number, Field(ge=0.0, le=90.0)], Annotated[Number, Field(ge=0.0, le=90.0)]],
        AfterValidator(ordered),
    ] = (5.0, 25.0)
    # Recall reaches 0 when this share lies outside the image (above 0: a ramp, not a step).
    truncation_zero: Annotated[Number, Field(ge=0.01, le=1.0)] = 0.8
    visible_fraction: FractionPair = (0.15, 0.7)  # occlusion ramp: 0 at first, full at second
    miss_correlation_s: NonNegative = (
        1.0  # correlation time of the detector's luck (0: independent)
    )
    viewpoint: Flag = True


@dataclass(frozen=True)
class MaskSpec:
    """How object masks differ from the true visible silhouette."""

    __pydantic_config__ = CHECKED
    boundary_leak_px: Count = 1  # every mask grows this much onto whatever is behind
    partial_rate: Fraction = 0.15  # share of masks covering only part of the object
    partial_keep: FractionPair = (0.45, 0.85)  # the part kept, drawn uniformly
    split_rate: Fraction = 0.05  # share of objects reported as two detections (over-segmented)
    support_bleed_rate: Fraction = 0.25  # share of masks that spill onto the supporting surface
    support_bleed_px: CountPair = (3, 10)  # how far they spill, drawn uniformly


@dataclass(frozen=True)
class LabelSpec:
    """Which classes the detector mixes up, and how often."""

    __pydantic_config__ = CHECKED
    confusable: Groups = ()  # groups of classes mistaken for one another
    flicker: Fraction = 0.15  # per detection: another class of its confusable group
    confusion: Fraction = 0.01  # per detection: any other object class of the scenario
    # Share of those confusions whose class scores still carry the true class's group (the
    # rest score the reported class's own group: confidently wrong).
    confusion_keeps_truth: Fraction = 0.25


@dataclass(frozen=True)
class AppearanceSpec:
    """A CLIP-like appearance vector: shares of the squared norm (the rest is per-view noise).

    The class, instance, view and context shares add up to at most 1, as do the shared and
    group shares of a class vector.
    """

    __pydantic_config__ = CHECKED
    dim: PositiveInt | None = 64  # None (null in the file): the detector sends no embedding
    class_share: Fraction = 0.70  # common to every instance of a class
    instance_share: Fraction = 0.10  # this instance's look (a share of it its own, see below)
    view_share: Fraction = 0.09  # varies smoothly with the direction the object is seen from
    context_share: Fraction = 0.04  # what a crop shows around the object: common to one place
    shared_share: Fraction = 0.50  # of a class vector: common to every class (CLIP's narrow cone)
    group_share: Fraction = 0.35  # of a class vector: common to its confusable group
    # Mean share of an instance part that is the look's own (the rest looks like its class):
    # the overlap knob between one instance and another of its class (1: every look distinct).
    distinctiveness: Fraction = 0.5
    # Log-normal spread of a detection's noise share (0: fixed; 2 already spans e^4 = 55 x).
    noise_spread: Annotated[Number, Field(ge=0.0, le=2.0)] = 1.0
    look_alike: Groups = ()  # groups of object ids that look the same

    def __post_init__(self) -> None:
        shares = self.class_share + self.instance_share + self.view_share + self.context_share
        if shares > 1 + 1e-9:
            raise field_error("context_share", "class, instance, view and context shares exceed 1")
        if self.shared_share + self.group_share > 1.0 + 1e-9:
            raise field_error("group_share", "shared and group shares exceed 1")

    @property
    def noise_share(self) -> float:
        """What is left for per-detection noise (crop, blur, mask errors)."""
        shares = self.class_share + self.instance_share + self.view_share + self.context_share
        return max(0.0, 1.0 - shares)


@dataclass(frozen=True)
class PhantomSpec:
    """A persistent false positive: a flat picture (poster, reflection) read as an object."""

    __pydantic_config__ = CHECKED
    id: Text
    label: Text
    at: Vec3  # center of the picture, world frame
    size: tuple[Positive, Positive]  # width along the wall, height
    facing: Number  # yaw [rad] of the picture's normal (the side it is seen from)
    # Seen as an object only within this angle of its normal (a picture seen edge-on is none).
    cone_deg: Annotated[Number, Field(ge=1.0, le=90.0)] = 50.0
    recall: Fraction = 0.7  # how convincing it is: scales the viewpoint recall


@dataclass(frozen=True)
class FixtureDetectorSpec:
    """The open-vocabulary fixture segmenter (see `sim.fixture_segmenter`)."""

    __pydantic_config__ = CHECKED
    recall: Fraction = 0.9
    score_noise: NonNegative = 0.04
    min_visible_pixels: Count = 400
    ambiguity: Mapping[Text, Mapping[str, Fraction]] | None = None  # fixture id -> label: score
    partial_rate: Fraction = 0.3  # share of masks covering only part of the fixture
    partial_keep: FractionPair = (0.5, 0.9)
    bleed_rate: Fraction = 0.2  # share of masks spilling into an adjacent fixture
    bleed_px: CountPair = (4, 12)
    wrong_top_rate: Fraction = 0.10  # mean share of views whose top class is a wrong one
    # Beta concentration of that share per fixture (0: none; 1000 is already every fixture alike).
    ambiguity_concentration: Annotated[Number, Field(ge=0.0, le=1000.0)] = 5.0
    merge_rate: Fraction = 0.15  # share of views of two adjacent fixtures segmented as one mask
    # Adjacent: footprints at most this far apart, tops level (past 2 m nothing is adjacent).
    merge_gap_m: Annotated[Number, Field(ge=0.0, le=2.0)] = 0.20
    split_rate: Fraction = 0.10  # share of views of a long fixture segmented as two halves
    split_min_length_m: Positive = 1.6  # long: a footprint side at least this long
    # Hallucination sites per square metre of floor (1: a site on every square metre).
    spurious_per_m2: Annotated[Number, Field(ge=0.0, le=1.0)] = 0.05
    spurious_recall: Fraction = 0.30  # share of views in which a site in view is reported


@dataclass(frozen=True)
class DetectorSpec:
    """The simulated detector's error modes and the depth noise model."""

    __pydantic_config__ = CHECKED
    min_visible_pixels: Count = 150  # the smallest mask reported (at 640 x 480)
    # Rollouts only: the detector run on the keyframes the robot posts while it moves sees the
    # frame downsampled by this factor per axis (an object's pixel area counts scale^2 against
    # `min_visible_pixels` and the area recall); inspection captures run at full resolution.
    # At least 0.05: a 640 x 480 frame keeps 32 x 24 pixels.
    far_range_input_scale: Annotated[Number, Field(ge=0.05, le=1.0)] = 0.5
    recall: Annotated[RecallSpec, BeforeValidator(_flat_recall)] = field(default_factory=RecallSpec)
    masks: MaskSpec = field(default_factory=MaskSpec)
    labels: LabelSpec = field(default_factory=LabelSpec)
    appearance: AppearanceSpec = field(default_factory=AppearanceSpec)
    false_positives_per_frame: NonNegative = 0.05
    phantoms: tuple[PhantomSpec, ...] = ()
    score: Fraction = 0.9
    depth_noise: Literal["kinect", "none"] = "kinect"
    # null in the file: no fixture segmenter.
    fixtures: FixtureDetectorSpec | None = field(default_factory=FixtureDetectorSpec)

    def __post_init__(self) -> None:
        ids = [phantom.id for phantom in self.phantoms]
        for index, phantom_id in enumerate(ids):
            if phantom_id in ids[:index]:
                raise field_error(f"phantoms[{index}].id", f"{phantom_id!r} is used twice")

    @property
    def embedding_dim(self) -> int | None:
        """Size of the appearance vector (None: no embeddings)."""
        return self.appearance.dim


def correlation_per_frame(correlation_s: float, frame_period: float) -> float:
    """AR(1) coefficient between consecutive frames for a correlation time (0 s: independent)."""
    return 0.0 if correlation_s <= 0 else math.exp(-frame_period / correlation_s)
