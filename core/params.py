"""Every constant of the method, each with the paper section it comes from.

Values the paper leaves open are chosen here, named and documented. A scene records its
parameters in its log when it is created, so a replay always uses the values the events
were decided with.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Annotated, Any

import orjson
from pydantic import AfterValidator, ConfigDict, Field, TypeAdapter, ValidationError

from core.errors import InvalidParams, field_path

# Parameters are checked when a scene is created (and recorded only then): strict types (no
# "525" for a number, no true for an integer), finite numbers, ranges, no unknown keys.
_CHECKED = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False)


def _printable(label: str) -> str:
    if not label or len(label) > 100 or any(ord(c) < 32 or c == "\x7f" for c in label):
        raise ValueError("labels are 1-100 printable characters")
    return label


Label = Annotated[str, AfterValidator(_printable)]
Labels = Annotated[tuple[Label, ...], Field(min_length=1, max_length=64)]
Fraction = Annotated[float, Field(ge=0.0, le=1.0)]
Similarity = Annotated[float, Field(ge=-1.0, le=1.0)]
Metres = Annotated[float, Field(ge=0.0, le=100.0)]
PositiveMetres = Annotated[float, Field(gt=0.0, le=100.0)]
Count = Annotated[int, Field(ge=1, le=1_000_000)]
Weight = Annotated[float, Field(ge=0.0, le=100.0)]


@dataclass(frozen=True)
class ProposalParams:
    """Grounding a 2D mask into a 3D proposal (section 3.2, "Valid mask depth is back-projected")."""

    __pydantic_config__ = _CHECKED
    # Not numbered in the paper: fewer valid-depth pixels than this and the proposal is rejected.
    min_valid_depth_pixels: Count = 40
    # Robust inlier filtering against boundary leakage: keep |z - median z| <= max(band, k * MAD).
    depth_inlier_mad_k: Annotated[float, Field(gt=0.0, le=100.0)] = 3.0
    depth_inlier_min_band_m: Metres = 0.05
    # The median is taken on the mask eroded by this many pixels, which leakage cannot reach,
    # when at least `min_interior_pixels` valid pixels remain there.
    boundary_erosion_px: Annotated[int, Field(ge=0, le=16)] = 2
    min_interior_pixels: Count = 9
    # Box extent from robust percentiles of the inlier points, floored so a thin surface still
    # gives a box the visibility gate can sample.
    extent_percentiles: tuple[
        Annotated[float, Field(ge=0.0, le=100.0)], Annotated[float, Field(ge=0.0, le=100.0)]
    ] = (5.0, 95.0)
    min_extent_m: PositiveMetres = 0.04
    # Not in the paper: a mask with more valid-depth pixels than this is sampled on a stride
    # (20,000 samples fix a median and 5/95 percentiles to well under a millimetre of depth).
    max_mask_samples: Annotated[int, Field(ge=100, le=10_000_000)] = 20_000

    def __post_init__(self) -> None:
        if self.extent_percentiles[0] >= self.extent_percentiles[1]:
            raise ValueError("extent_percentiles: the low percentile must be below the high one")


@dataclass(frozen=True)
class AssociationParams:
    """Dynamic association front end (section 3.3, "Type-specific association")."""

    __pydantic_config__ = _CHECKED
    max_center_distance_m: PositiveMetres = 0.8
    min_appearance_cosine: Similarity = 0.78
    # "Class agreement": the paper's detectors agree on a label; ours flicker between confusable
    # classes (cup/mug), so agreement is sum_c p_track(c) q_det(c), the chance both name the
    # same class, with q the detection's class scores normalized (its label alone without them).
    # 0.2: a track seen as a mug agrees with a detection that scores cup 0.9 and mug 0.75 (0.45),
    # not with one that never names a mug.
    min_class_compatibility: Fraction = 0.2
    # Unique-class fallback: recover an identity after large motion when appearance agrees.
    unique_class_fallback: bool = True
    # Among several missing tracks of a class, appearance must prefer one by this much: two
    # instances of a class sit 0.70-0.85 apart in CLIP-like spaces, one instance 0.80-0.95.
    fallback_margin: Fraction = 0.05
    # Only a track whose absence is established lends its identity: removed or demoted, or its
    # place seen empty in this many batches (one miss may be the detector's, not the object's).
    fallback_min_misses: Annotated[int, Field(ge=1, le=1000)] = 2
    # Not in the paper: detectors over-segment (one mug reported as two masks). A second
    # proposal of a compatible class whose box, joined with the box of a proposal matched in the
    # same frame, stays within this factor of the object's size on every axis is a piece of that
    # object, not a new one: two solid objects of that size side by side span at least twice it.
    # 0 switches the rule off (every unmatched proposal is a new hypothesis, as in the paper).
    fragment_max_growth: Annotated[float, Field(ge=0.0, le=10.0)] = 1.5


# The log-odds clamp may not exceed this: logistic() of it is still distinguishable from 1.
MAX_LOGODDS = 30.0


@dataclass(frozen=True)
class ExistenceParams:
    """Existence log-odds, equation (3) (section 3.3, "Visibility-gated existence")."""

    __pydantic_config__ = _CHECKED
    eta_observed: Weight = 1.0  # eta_o, ordinary positive observation
    eta_confirmed: Weight = 1.8  # eta_c, cached verification confirm
    eta_missed: Weight = 0.70  # eta_m, visibility-admissible miss
    eta_rejected: Weight = 2.20  # eta_r, cached verification reject
    # Not given by the paper: a new hypothesis (and a removed track that is re-acquired) starts
    # from an uninformed prior, p = 0.5.
    prior_logodds: Annotated[float, Field(ge=-MAX_LOGODDS, le=MAX_LOGODDS)] = 0.0
    # Not given by the paper: the clamp. Without one an object seen 500 times could never be
    # removed; with +-4 (p in [0.018, 0.982]) a long-seen object needs 9 visible misses
    # ((4 + 1.99) / 0.7) to fall to p <= 0.12, and a removed one recovers in 5 positive batches.
    logodds_min: Annotated[float, Field(ge=-MAX_LOGODDS, le=MAX_LOGODDS)] = -4.0
    logodds_max: Annotated[float, Field(ge=-MAX_LOGODDS, le=MAX_LOGODDS)] = 4.0

    def __post_init__(self) -> None:
        if not self.logodds_min <= self.prior_logodds <= self.logodds_max:
            raise ValueError("logodds_min <= prior_logodds <= logodds_max must hold")
        if self.logodds_min >= self.logodds_max:
            raise ValueError("logodds_min must be below logodds_max")


@dataclass(frozen=True)
class VisibilityParams:
    """The geometric visibility gate V_i(t) (section 3.3)."""

    __pydantic_config__ = _CHECKED
    # Valid camera range; not numbered in the paper, chosen for Kinect-class RGB-D sensors.
    min_range_m: Metres = 0.3
    max_range_m: PositiveMetres = 6.0
    depth_window_px: Annotated[int, Field(ge=1, le=31)] = 5  # "valid depth in a 5x5 window"
    occlusion_margin_m: Metres = 0.15  # unoccluded when d_meas + 0.15 m >= d_expected
    min_samples_passed: Count = 2  # V = 1 only when at least two samples pass
    # Samples of the stored box: a grid of n per axis (27 = corners, edge and face centres,
    # centre). At most 9 (729 samples per track) bounds the gate's work per frame.
    box_samples_per_axis: Annotated[int, Field(ge=1, le=9)] = 3
    # Not in the paper: the missed-detection condition. A miss is evidence of absence only when
    # the observable part of the box (its projection inside the image, times the share of its
    # samples that passed) covers at least this share of the image: 0.0005 is about 150 pixels
    # at 640 x 480, below which detectors rarely report a mask (COCO calls objects under 32 x 32
    # pixels small and detects them worst). A sliver at the border, a grazing or a far view
    # passes two samples of the gate but would not have been detected: it is not a miss.
    min_expected_image_fraction: Fraction = 0.0005
    # And at least this share of the box's projection must lie inside the image: detectors
    # rarely report an object cut down to a strip by the image border.
    min_in_image_share: Fraction = 0.5

    def __post_init__(self) -> None:
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")
        if self.depth_window_px % 2 == 0:
            raise ValueError("depth_window_px must be odd (a window centred on the pixel)")
        if self.min_samples_passed > self.box_samples_per_axis**3:
            raise ValueError("min_samples_passed exceeds the box_samples_per_axis**3 samples")


@dataclass(frozen=True)
class FusionParams:
    """Persistent state fusion (section 3.3, "Persistent state fusion")."""

    __pydantic_config__ = _CHECKED
    observation_evidence_weight: Annotated[float, Field(gt=0.0, le=100.0)] = 1.0  # unit evidence
    verification_evidence_weight: Annotated[float, Field(gt=0.0, le=100.0)] = 3.0  # cached VLM
    max_recent_centers: Annotated[int, Field(ge=2, le=1024)] = 32  # Sigma_i over the last 32
    fixture_center_alpha: Annotated[float, Field(gt=0.0, le=1.0)] = 0.35  # EMA of fixture centers
    # Not in the paper: the visibility gate samples the union of an object's observed boxes
    # (partial views give partial boxes); past this size on an axis the union is dropped for
    # the latest box, as no object we track is larger and drift must not inflate it.
    max_box_m: Annotated[float, Field(gt=0.0, le=10.0)] = 1.0


@dataclass(frozen=True)
class LifecycleParams:
    """Lifecycle transitions and audit events (section 3.3)."""

    __pydantic_config__ = _CHECKED
    # Thresholds on p_exist; 0 or 1 switch a transition off (baselines do that).
    confirm_min_p_exist: Fraction = 0.72
    confirm_min_batches: Annotated[int, Field(ge=1, le=1000)] = 2  # cross-batch confirmation
    move_min_distance_m: PositiveMetres = 0.35
    demote_below_p_exist: Fraction = 0.30
    remove_at_most_p_exist: Fraction = 0.12
    remove_min_visible_misses: Annotated[int, Field(ge=1, le=1000)] = 3
    # Not in the paper: a hypothesis never published and not seen again for this long retires
    # (a false positive, a glimpse): it leaves the association pool and the visibility gate, so
    # a frame's work is bounded by the memory in play, not by every blob ever seen.
    retire_unseen_hypothesis_s: Annotated[float, Field(gt=0.0, le=1e9)] = 60.0
    # Not in the paper: without appearance, a match resets the miss count (and adds existence
    # evidence) only at the track's place: its center within the stored box grown by this.
    # A same-label false positive elsewhere inside the 0.8 m gate then cannot keep a vanished
    # object alive; a moved object is corroborated from its second sighting at the new place.
    place_tolerance_m: Metres = 0.10


SizeLimits = tuple[Metres, Metres, Metres, Metres, Metres, Metres]  # min dx, dy, dz, max dx, dy, dz


@dataclass(frozen=True)
class FixtureParams:
    """Coarse fixtures: voxel class evidence, DBSCAN, association and promotion (sections 3.2, 3.3).

    The paper gives the structure and reports its exact fixture gates in its supplementary
    material, which we do not have; the numbers here are ours, chosen for indoor furniture.
    """

    __pydantic_config__ = _CHECKED
    taxonomy: Labels = ("table", "desk", "counter", "bed", "shelf", "cabinet", "sofa")
    # Only these classes enter the inspection queue Q_t (section 3.4, T_insp).
    inspection_taxonomy: Annotated[tuple[Label, ...], Field(max_length=64)] = (
        "table",
        "desk",
        "counter",
        "shelf",
    )
    # At least 2 cm: finer voxels would let one fixture mask cover millions of them.
    voxel_size_m: Annotated[float, Field(ge=0.02, le=1.0)] = 0.05
    # Every 4th pixel of a fixture mask in each direction: at 6 m that is 4.6 cm, still inside
    # one 5 cm voxel, and it makes the map 16 times cheaper to feed.
    mask_pixel_stride: Annotated[int, Field(ge=1, le=64)] = 4
    # Voxels one batch's fixture masks may add to the map. A 2 x 1 m table top seen at 5 cm is
    # about 800 voxels, a whole room's furniture in one frame a few 10,000: the budget bounds the
    # work and the event of a batch of hostile masks (flat noise depth), not real evidence.
    max_voxels_per_batch: Annotated[int, Field(ge=1, le=10_000_000)] = 200_000
    # Sampled mask points one batch's fixture masks may back-project (the work behind the
    # voxels): 2,000,000 are 100 VGA fixture masks at the stride above, or 13 full masks of a
    # 2.4 MP frame. Masks past it add nothing to the batch.
    max_points_per_batch: Annotated[int, Field(ge=1, le=100_000_000)] = 2_000_000
    # A voxel is kept for class c when its mean similarity to c reaches the threshold of c and
    # beats every competing class by the margin.
    default_class_threshold: Similarity = 0.40
    class_thresholds: dict[Label, Similarity] = field(default_factory=dict)
    min_class_margin: Fraction = 0.02
    # DBSCAN in metric space over kept voxel centres (eps spans the 26-neighbourhood).
    dbscan_eps_m: Annotated[float, Field(gt=0.0, le=2.0)] = 0.09
    dbscan_min_points: Annotated[int, Field(ge=1, le=1000)] = 4
    # Plausible sizes per class: min dx, dy, dz, max dx, dy, dz (dx >= dy: footprint sorted).
    default_size_limits: SizeLimits = (0.25, 0.20, 0.10, 4.0, 2.5, 2.5)
    size_limits: dict[Label, SizeLimits] = field(
        default_factory=lambda: {
            "table": (0.4, 0.3, 0.3, 3.5, 2.0, 1.2),
            "desk": (0.5, 0.3, 0.4, 3.0, 1.5, 1.2),
            "counter": (0.5, 0.3, 0.5, 5.0, 1.5, 1.3),
            "bed": (1.2, 0.7, 0.2, 2.6, 2.4, 1.2),
        }
    )
    # Association: same class, planar center distance, expanded-footprint coverage or IoU.
    max_planar_distance_m: PositiveMetres = 1.0
    # Class agreement of a cluster and a track: the same class, or the track's class within
    # this of the cluster's best mean similarity (a desk the segmenter scores 0.50 desk and
    # 0.47 table agrees with a table track; a table scoring 0.9 table and 0.3 desk does not).
    compatible_class_margin: Fraction = 0.05
    footprint_expand_m: Metres = 0.25
    min_expanded_coverage: Fraction = 0.6
    min_footprint_iou: Fraction = 0.25
    # A residual cluster this much inside a matched fixture's expanded footprint is absorbed.
    residual_containment: Fraction = 0.9
    # Promotion: support from several temporally distinct batches, then the consensus gate.
    confirm_min_batches: Annotated[int, Field(ge=1, le=1000)] = 3
    consensus_min_agreement: Fraction = 0.8  # share of supporting batches whose top class agrees
    consensus_min_margin: Fraction = 0.08  # mean top-vs-second margin of those batches
    # Support: an object rests on a fixture when its bottom is this close to the fixture top
    # and its center is inside the fixture footprint grown by the margin.
    support_height_tolerance_m: Metres = 0.08
    support_footprint_margin_m: Metres = 0.05

    def __post_init__(self) -> None:
        if len(set(self.taxonomy)) != len(self.taxonomy):
            raise ValueError("taxonomy: a class is listed twice")
        for name, limits in {"default": self.default_size_limits, **self.size_limits}.items():
            if any(limits[i] > limits[i + 3] for i in range(3)):
                raise ValueError(f"size limits of {name}: a minimum exceeds its maximum")


@dataclass(frozen=True)
class InspectionParams:
    """Fixture-centered inspection capture (sections 3.2 and 3.4)."""

    __pydantic_config__ = _CHECKED
    max_attempts: Annotated[int, Field(ge=1, le=100)] = 3  # bounded retry, then abandoned
    min_support_samples: Count = 2  # support-region samples that must pass the visibility gate
    nms_mask_iou: Fraction = 0.5  # same-class non-maximum suppression
    cross_class_mask_iou: Fraction = 0.7  # cross-class overlap suppression


@dataclass(frozen=True)
class Params:
    """The whole parameter tree of one scene."""

    __pydantic_config__ = _CHECKED
    proposal: ProposalParams = field(default_factory=ProposalParams)
    association: AssociationParams = field(default_factory=AssociationParams)
    existence: ExistenceParams = field(default_factory=ExistenceParams)
    visibility: VisibilityParams = field(default_factory=VisibilityParams)
    fusion: FusionParams = field(default_factory=FusionParams)
    lifecycle: LifecycleParams = field(default_factory=LifecycleParams)
    fixtures: FixtureParams = field(default_factory=FixtureParams)
    inspection: InspectionParams = field(default_factory=InspectionParams)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (tuples become lists)."""
        result: dict[str, Any] = _jsonable(asdict(self))
        return result

    @classmethod
    def from_dict(cls, overrides: Mapping[str, Any] | None = None) -> Params:
        """The defaults deep-merged with a (possibly partial) nested dict, then validated.

        InvalidParams names the first offending field (`params.visibility.depth_window_px`).
        """
        return _validated(orjson.dumps(overrides or {}, option=orjson.OPT_SORT_KEYS))


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _jsonable(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(item) for item in value]
    return value


def deep_merge(defaults: dict[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Nested objects merge key by key (per-class maps too); anything else replaces."""
    merged = dict(defaults)
    for key, value in overrides.items():
        current = merged.get(key)
        if isinstance(current, dict) and isinstance(value, Mapping):
            merged[key] = deep_merge(current, value)
        else:
            merged[key] = value
    return merged


_ADAPTER: TypeAdapter[Params] = TypeAdapter(Params)


@functools.lru_cache(maxsize=256)
def _validated(overrides: bytes) -> Params:
    """Params from canonical JSON overrides (cached: every replay and snapshot reads them)."""
    merged = deep_merge(DEFAULT_PARAMS.to_dict(), orjson.loads(overrides))
    try:
        return _ADAPTER.validate_json(orjson.dumps(merged), strict=True)
    except ValidationError as error:
        first = error.errors()[0]
        location = [part for part in first["loc"] if not str(part).startswith("function-")]
        path = field_path(["params", *location]) or "params"
        reason = (
            "unknown parameter"
            if first["type"] == "unexpected_keyword_argument"
            else first["msg"].removeprefix("Value error, ")
        )
        more = f" (and {error.error_count() - 1} more)" if error.error_count() > 1 else ""
        raise InvalidParams(f"{path}: {reason}{more}", path) from None


DEFAULT_PARAMS = Params()
