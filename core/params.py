"""Every constant of the method, each with the paper section it comes from.

Values the paper leaves open are chosen here, named and documented. A scene records its
parameters in its log when it is created, so a replay always uses the values the events
were decided with.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Annotated, Any, Literal

import orjson
from pydantic import AfterValidator, ConfigDict, Field, TypeAdapter, ValidationError

from core.errors import InvalidParams, field_path
from core.params_shape import check_shape

# Parameters are checked when a scene is created (and recorded only then): strict types (no
# "525" for a number, no true for an integer), finite numbers, ranges, no unknown keys.
_CHECKED = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False)


def _refused(character: str) -> bool:
    """A control, DEL, a lone surrogate or a non-character: what the service's text rule
    refuses in every name and label, as XML and strict JSON consumers do."""
    code = ord(character)
    return (
        code < 32
        or code == 0x7F
        or 0xD800 <= code <= 0xDFFF
        or 0xFDD0 <= code <= 0xFDEF
        or code & 0xFFFE == 0xFFFE
    )


def _printable(label: str) -> str:
    if not label or len(label) > 100 or any(_refused(c) for c in label):
        raise ValueError("labels are 1-100 printable characters (no control or non-character)")
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
    # The soft reading above is ours (switch `soft_class_agreement`); False is the paper's
    # "class agreement": the detection's label is the track's most likely class.
    soft_class_agreement: bool = True
    # Unique-class fallback: recover an identity after large motion when appearance agrees.
    unique_class_fallback: bool = True
    # Among several missing tracks of a class, appearance must prefer one by this much: two
    # instances of a class sit 0.70-0.85 apart in CLIP-like spaces, one instance 0.80-0.95.
    fallback_margin: Fraction = 0.05
    # Only a track whose absence is established lends its identity: removed or demoted, or its
    # place seen empty in this many batches (one miss may be the detector's, not the object's).
    fallback_min_misses: Annotated[int, Field(ge=1, le=1000)] = 2
    # Not in the paper: the two sentences above (lend only a published identity whose absence
    # is established). False is the paper's fallback, which lends the identity of any track of
    # the class that this frame did not match.
    fallback_requires_absence: bool = True
    # Not in the paper: among several candidates of the class, appearance picks one (past the
    # gate, by `fallback_margin`). False is the paper's "unique-class" fallback: one candidate
    # of the class and one unmatched proposal of it, appearance not conflicting.
    fallback_ranks_by_appearance: bool = True
    # The fallback, deferred (not in the paper, whose fallback lends an identity at once): a
    # carried object seen at its new place before its old place was seen empty starts a
    # hypothesis. Once its absence is established as above, a never-published hypothesis seen
    # since, of a compatible class, takes the identity back when each is the other's best
    # appearance match past the gate and by the margin (`ObjectReidentified`). Off with the
    # fallback.
    reidentify_hypotheses: bool = True
    # The hand-over (ours): the re-identification above also takes in a published track, first
    # seen after the missing object was last seen and not itself seen empty. A carried object
    # seen at its new place first is published there within two batches, long before its old
    # place is seen empty; the younger track then retires into the object, which keeps its
    # identity at the new place (`ObjectReidentified`, then `reparent`). False: only a
    # never-published hypothesis takes an identity back.
    reidentify_published: bool = True
    # Ours: in the fallback and the re-identification, the unrefuted tracks of the class compete
    # too (published, not removed or demoted, not seen empty as above, not matched in the
    # frame): an identity is lent only when its track beats every one of them by the margin, and
    # when one of them wins nothing is lent yet (it may be the object, still in place or not yet
    # known to be gone). False: only the tracks whose absence is established are compared.
    unrefuted_rivals: bool = True
    # Ours (`claimed_hypotheses`): a hypothesis whose appearance singles out a published object
    # of a compatible class last seen before it (missing, or unrefuted and not seen in this
    # batch: cosine past the gate by `fallback_margin`, and by the margin over every other such
    # object) is not published yet: it may be that object, carried here. Published,
    # it would take a second identity, and handing the old one back later is a second switch.
    # It waits until that object is seen elsewhere (then they are two), its absence is
    # established (then the hypothesis takes its identity back), or it has been seen in this
    # many batches (then it is published as a new object). 0: published as the paper says.
    claimed_hold_max_batches: Annotated[int, Field(ge=0, le=1000)] = 8
    # Not in the paper: detectors over-segment (one mug reported as two masks). A second
    # proposal of a compatible class whose box, joined with the box of a proposal matched in the
    # same frame, stays within this factor of the object's size on every axis is a piece of that
    # object, not a new one: two solid objects of that size side by side span at least twice it.
    # The size is upright: its larger horizontal side on x and y, its height on z (objects turn
    # about the vertical, and one view shows the far side only in part).
    # 0 switches the rule off (every unmatched proposal is a new hypothesis, as in the paper).
    fragment_max_growth: Annotated[float, Field(ge=0.0, le=10.0)] = 1.5
    # Not in the paper: split at its first sighting, one object makes two hypotheses that
    # nothing tells from two objects side by side. Once a batch matches one of them and the
    # other's center lies inside its object box (its center and extent; or the other's box
    # holds its center), with a compatible class and agreeing appearance, neither demoted nor
    # removed, they are one object: the younger track retires as merged into the older (an
    # unpublished one into a published one). Left, the second track stays published, since the
    # depth at its place shows the object's own surface and it takes no visible misses. (The
    # box the visibility gate samples, the union of every view, is not used: it grows with
    # bleeding masks and would take in a neighbour.) False: the paper's rule.
    absorb_contained_tracks: bool = True


# The log-odds clamp may not exceed this: logistic() of it is still distinguishable from 1.
MAX_LOGODDS = 30.0
# Section 3.4's support-region test samples the fixture's top surface as a slab this thick [m]
# (the paper names the region, not its depth; ours). A constant, not a field: scene params
# already written to logs must replay to the same state byte for byte.
SUPPORT_SLAB_M = 0.02


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
    # Not given by the paper: the clamp. Its top is how far past sightings may outweigh what
    # the robot sees now: without one an object seen 500 times could never be removed. At 1.5
    # (p 0.82) any object, however long seen, is demoted after 4 visibility-admissible misses
    # and removed after 5 ((1.5 + 1.99) / 0.7): one look at its place, a few batches in which
    # the depth shows the place empty (a miss counts only then, see VisibilityParams). A top of
    # 4 (p 0.982) needed 9 misses, in practice a second visit to the place; measured side by
    # side on the realistic streams (evaluation/README.md): events reflected within 10 batches
    # 33/60 -> 42/60, IDF1 .900 -> .911, identity-agnostic false absence .033 -> .037 (mostly
    # moved objects whose old node, kept longer, had stood within 0.5 m of them). The
    # bottom must lie under logit(0.12) = -1.99 for removal to be reachable: at -4 (p 0.018) a
    # removed object is confirmed again after 5 positive batches.
    logodds_min: Annotated[float, Field(ge=-MAX_LOGODDS, le=MAX_LOGODDS)] = -4.0
    logodds_max: Annotated[float, Field(ge=-MAX_LOGODDS, le=MAX_LOGODDS)] = 1.5
    # Ours (`clear_view_misses`): a visible miss counts up to this many times eta_m, by how
    # clearly the view showed the place (`core.existence.miss_weight`); 1 is the paper's U V.
    # Removal from the clamp's top then takes 3 clear misses ((1.5 + 1.99) / 1.4), one pass of
    # the route by the place (a pass brings two or three admissible views), instead of 5, and a
    # glimpse still counts once. Clear from `clear_view_image_fraction` on: 1,024 pixels at
    # 640 x 480, COCO's smallest "medium" object (32 x 32), the size from which detectors
    # rarely miss one.
    clear_view_miss_weight: Annotated[float, Field(ge=1.0, le=10.0)] = 2.0
    clear_view_image_fraction: Fraction = 0.0033

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
    # Not in the paper: a miss is evidence of absence only when the depth shows the place
    # empty. The ray to the object's centre mu_i (the robust median of its latest accepted
    # observation) must meet the first surface at least this far behind it (the 5x5 window
    # median): an object still there but missed by the detector puts its own surface in front
    # of its centre, while an empty place shows what lies behind it (the support, the wall).
    # The centre of the box the gate samples is not used: a mask bleeding onto a grazing
    # support grows that union box far beside a small object, and its ray then misses it.
    # 0.03 m is about twice the axial noise of a Kinect-class sensor at 3 m (Nguyen et al.
    # 2012: sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m). False is the paper's gate. A hollow
    # object seen from above (a bowl) can show its inside bottom behind its centre; for it the
    # rule can fall back to the paper's.
    miss_requires_empty_center: bool = True
    empty_center_margin_m: Metres = 0.03

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
    # Not in the paper: an observation's unit class evidence is spread over the classes the
    # detector scored (its scores clipped at 0 and normalized), so a label flickering between
    # confusable classes (cup/mug) builds one class belief. False is the paper's: the unit
    # evidence goes to the detection's label.
    class_evidence_from_scores: bool = True


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
    # The rule above, as a switch: False is the paper's, where every matched batch is an
    # ordinary positive observation (eta_o), wherever in the gate the match lay.
    corroborate_at_place: bool = True


SizeLimits = tuple[Metres, Metres, Metres, Metres, Metres, Metres]  # min dx, dy, dz, max dx, dy, dz
# Class scores one batch's voxels may carry (voxels x taxonomy classes): 2,000,000 float64 are
# 16 MB per array, and merging a batch into the map takes a few such arrays. The defaults
# (200,000 voxels, 7 classes) use 1,400,000.
MAX_CLASS_SCORE_CELLS = 2_000_000


@dataclass(frozen=True)
class FixtureParams:
    """Coarse fixtures: voxel class evidence, DBSCAN, association and promotion (sections 3.2, 3.3).

    The paper gives the structure and reports its exact fixture gates in its supplementary
    material, which we do not have; the numbers here are ours, chosen for indoor furniture.
    """

    __pydantic_config__ = _CHECKED
    taxonomy: Labels = ("table", "desk", "counter", "bed", "shelf", "cabinet", "sofa")
    # Only these classes enter the inspection queue Q_t (section 3.4, T_insp; the paper leaves
    # the set to the task). Every class of the taxonomy above holds small objects in a home (a
    # phone on a nightstand, which is a cabinet; glasses on a bed; a remote on a sofa), so all
    # are inspected; a task that tracks only kitchenware may name fewer.
    inspection_taxonomy: Annotated[tuple[Label, ...], Field(max_length=64)] = (
        "table",
        "desk",
        "counter",
        "bed",
        "shelf",
        "cabinet",
        "sofa",
    )
    # At least 2 cm: finer voxels would let one fixture mask cover millions of them.
    voxel_size_m: Annotated[float, Field(ge=0.02, le=1.0)] = 0.05
    # Every 4th pixel of a fixture mask in each direction: at 6 m that is 4.6 cm, still inside
    # one 5 cm voxel, and it makes the map 16 times cheaper to feed.
    mask_pixel_stride: Annotated[int, Field(ge=1, le=64)] = 4
    # Voxels one batch's fixture masks may add to the map. A 2 x 1 m table top seen at 5 cm is
    # about 800 voxels, a whole room's furniture in one frame a few 10,000: the budget bounds the
    # work and the event of a batch of hostile masks (flat noise depth), not real evidence.
    # At most 1,000,000, and at most MAX_CLASS_SCORE_CELLS / len(taxonomy): each voxel carries a
    # score per class, and a batch's voxels times the classes are the arrays merged into the map.
    max_voxels_per_batch: Annotated[int, Field(ge=1, le=1_000_000)] = 200_000
    # Sampled mask points one batch's fixture masks may back-project (the work behind the
    # voxels): 2,000,000 are 100 VGA fixture masks at the stride above, or 13 full masks of a
    # 2.4 MP frame. Masks past it add nothing to the batch. At most 10,000,000: 4 full masks at
    # stride 1 of the largest frame the service admits by default.
    max_points_per_batch: Annotated[int, Field(ge=1, le=10_000_000)] = 2_000_000
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
    # Not in the paper: a second track of one fixture is absorbed the same way. Seen in parts
    # first (a shelf end, half a desk), one fixture can make two hypotheses; once a batch's
    # cluster matches a confirmed track whose expanded footprint holds the other track's
    # footprint by `residual_containment`, the other one is retired as merged into it (its
    # objects reparented). Unmatched and in place, it would otherwise take no visible misses
    # (the depth there shows the fixture's own surface) and stay published. False: the
    # paper's rule, where such a track stays.
    absorb_contained_tracks: bool = True
    # Not in the paper: a fixture's voxels are kept per class, so a desk the segmenter calls a
    # table in some views can give two clusters, and two tracks, of two classes in one place
    # (label flicker would make duplicate fixtures). Two fixtures cannot stand in one
    # footprint at one height: a second track whose footprint has at least this IoU with the
    # keeper's (their unexpanded footprints) and whose top lies within `same_place_max_top_gap_m`
    # of the keeper's is merged into it like a contained track of its class, when the keeper
    # has more supporting batches (the better-supported class stands; the consensus gate still
    # judges it). 0.5: a fixture beside another, even pushed against it, overlaps it far less;
    # one seen in part first (half a desk) is held by the rule above. 1.0 switches it off.
    same_place_min_iou: Fraction = 0.5
    # A cabinet under a counter shares its footprint but not its top: 0.15 m is about three
    # voxels of the map, more than a flat top's spread between two views, less than any
    # furniture of the taxonomy stacked on another.
    same_place_max_top_gap_m: Metres = 0.15
    # Promotion: support from several temporally distinct batches, then the consensus gate.
    confirm_min_batches: Annotated[int, Field(ge=1, le=1000)] = 3
    consensus_min_agreement: Fraction = 0.8  # share of supporting batches whose top class agrees
    consensus_min_margin: Fraction = 0.08  # mean top-vs-second margin of those batches
    # Support: an object rests on a fixture when its bottom is this close to the fixture top
    # and its center is inside the fixture footprint grown by the margin.
    support_height_tolerance_m: Metres = 0.08
    support_footprint_margin_m: Metres = 0.05
    # Not in the paper (it gives no support geometry): a fixture's top is the upper face of
    # its highest voxel, so it is known only to within a band this deep under it (one voxel),
    # and mask spill onto a wall or an object above the top lifts it by another; the object's
    # bottom is measured against the band, not the face (an object on a desk whose top voxel
    # is 0.09 m above the desk's true top). 0: against the face alone.
    support_top_band_m: Annotated[float, Field(ge=0.0, le=0.5)] = 0.05
    # Not in the paper: among fixtures an object rests on, a published one wins over a fixture
    # hypothesis (an `on` edge names a node of the graph), then the closest top. False: the
    # closest top alone (the paper's "geometrically assigned parent").
    published_parent_first: bool = True

    def __post_init__(self) -> None:
        if len(set(self.taxonomy)) != len(self.taxonomy):
            raise ValueError("taxonomy: a class is listed twice")
        if self.max_voxels_per_batch * len(self.taxonomy) > MAX_CLASS_SCORE_CELLS:
            raise ValueError(
                f"max_voxels_per_batch: at most {MAX_CLASS_SCORE_CELLS // len(self.taxonomy):,} "
                f"for a taxonomy of {len(self.taxonomy)} classes (voxels x classes <= "
                f"{MAX_CLASS_SCORE_CELLS:,})"
            )
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
    # Which of the sweep's contract-valid views (its support region visible) is the primary,
    # the one view grounded (section 3.4: "one contract-valid primary view"; the paper does
    # not say which). "first": the first, in the sweep's order (the paper's reading). Not in
    # the paper, "most_grounded": the one whose grounded proposals resting on the fixture
    # stand for the most objects another valid view corroborates, then the most objects, the
    # first on ties (a detector that misses an object in the primary view but reports it in an
    # alternate; still one view's proposals, never fused; `core.sweep.view_score`).
    primary_view: Literal["first", "most_grounded"] = "most_grounded"
    # Not in the paper: each proposal of the primary view takes the label most of the valid
    # views give the object there, the primary's own on ties (a mug labelled cup in one view
    # of three). Its geometry and appearance stay the primary view's (`core.sweep`).
    sweep_class_votes: bool = True


@dataclass(frozen=True)
class OccupancyParams:
    """The 2D occupancy map A_t (section 3.1: "range measurements used to maintain a 2D
    occupancy map"; section 3.2: "range sensing incrementally expands the known region of A_t").

    The paper gives no grid parameters; these are ours. The world frame has z up and the floor
    at z = 0 (the simulator and a robot's map frame do). Each batch's depth says, per cell,
    "occupied" (a point in the robot's height band fell in it) or "free" (a ray to a measured
    point crossed it); occupied wins within a batch. Folded into an integer per cell:
    occupied adds `occupied_hit`, free subtracts `free_hit`, clamped to
    [`min_value`, `max_value`]; a cell is occupied while its value is above 0, free otherwise,
    and unknown until some batch spoke of it. Integers, so a replay is exact.
    """

    __pydantic_config__ = _CHECKED
    # 5 cm: the fixture voxel size; a 20 m x 20 m map is 400 x 400 cells.
    resolution_m: Annotated[float, Field(ge=0.02, le=1.0)] = 0.05
    # The map covers |x|, |y| <= this around the world origin; evidence beyond it is dropped
    # (a hostile pose 10 km away must not allocate a continent of cells).
    half_extent_m: Annotated[float, Field(ge=1.0, le=200.0)] = 100.0
    # The robot's height band: points between these heights above the floor are obstacles;
    # below the band is floor (free, not an obstacle: depth noise on the floor is a few cm),
    # above it the robot passes under (ceilings, hanging lamps). 1.5 m: a service robot's head.
    band_min_z_m: Annotated[float, Field(ge=-1.0, le=5.0)] = 0.10
    band_max_z_m: Annotated[float, Field(ge=0.0, le=5.0)] = 1.5
    # Valid depth range for the map (the visibility gate's Kinect-class range).
    min_range_m: Metres = 0.3
    max_range_m: PositiveMetres = 6.0
    # Every 4th pixel in each direction (as the fixture voxel map samples its masks).
    pixel_stride: Annotated[int, Field(ge=1, le=64)] = 4
    # Each sampled depth is the median of the valid depths in this window (pixels; 1: the raw
    # pixel), as depth is filtered before it is fused (KinectFusion filters it bilaterally).
    # Raw, the axial noise's outliers in front of surfaces pile up as occupied cells no free
    # ray clears: the boundaries grew 10-15 cm over a rollout and closed a 1 m door on the map.
    depth_median_px: Annotated[int, Field(ge=1, le=9)] = 3
    # Rays: one per bearing bin from the camera, as a laser scan from depth; a bin is clear up
    # to its nearest obstacle point, or, with none, to its farthest floor point. Bins this
    # wide leave no gap between rays wider than half a cell at the maximum range.
    ray_bins_per_cell_at_max_range: Annotated[int, Field(ge=1, le=16)] = 2
    # Stop the free ray this short of the obstacle (its cell is occupied, not free).
    ray_stop_short_m: Metres = 0.05
    # The robot stood where its camera was: the cells within this of the camera's floor
    # projection are free (the planner's robot radius; 0 for a camera not on the robot).
    footprint_radius_m: Annotated[float, Field(ge=0.0, le=5.0)] = 0.25
    occupied_hit: Annotated[int, Field(ge=1, le=16)] = 2
    free_hit: Annotated[int, Field(ge=1, le=16)] = 1
    # -1: one occupied batch makes any free cell occupied (obstacles appear at once, safe for
    # navigation); +6: a wall seen in 3 batches needs 6 batches of free rays through it to clear.
    min_value: Annotated[int, Field(ge=-100, le=0)] = -1
    max_value: Annotated[int, Field(ge=1, le=100)] = 6

    def __post_init__(self) -> None:
        if self.band_min_z_m >= self.band_max_z_m:
            raise ValueError("band_min_z_m must be below band_max_z_m")
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")
        if self.depth_median_px % 2 == 0:
            raise ValueError("depth_median_px must be odd (a window centred on its pixel)")
        if 2 * self.half_extent_m / self.resolution_m > 8192:
            raise ValueError("the map may have at most 8192 cells per side (half_extent_m)")


@dataclass(frozen=True)
class UncertaintyParams:
    """Fixture uncertainty u_i = w . phi_i, equation (4) (section 3.4).

    The weights are the paper's. Each phi term increases from 0 to 1; the paper names the terms
    and two transforms (existence ambiguity 4p(1-p); class uncertainty from normalized class
    entropy and score-margin ambiguity) and leaves the rest open: the transforms below are
    ours, fixed here before any evaluation.
    """

    __pydantic_config__ = _CHECKED
    # w = (.20, .30, .10, .15, .10, .15) over existence, class, parent, position, age, confirmation
    weight_existence: Fraction = 0.20
    weight_class: Fraction = 0.30
    weight_parent: Fraction = 0.10
    weight_position: Fraction = 0.15
    weight_age: Fraction = 0.10
    weight_confirmation: Fraction = 0.15
    # Class: share * H(p_cls) / log K + (1 - share) * clip(1 - m / class_margin_full, 0, 1), with
    # K the number of classes (the taxonomy, at least) and m the mean top-vs-second score margin
    # of the supporting batches (what the consensus gate reads). Equal shares; a margin of twice
    # the consensus gate's (2 x 0.08) is unambiguous.
    class_entropy_share: Fraction = 0.5
    class_margin_full: Annotated[float, Field(gt=0.0, le=1.0)] = 0.16
    # Parent: normalized entropy of p_parent (0 with one candidate or none: a fixture stands on
    # the floor).
    # Position: the planar spread of the recent centers, sqrt(S_xx + S_yy) / this, clipped
    # (1 with fewer than two centers): 0.30 m is a third of a table's width.
    position_sigma_full_m: PositiveMetres = 0.30
    # Age: (scene clock - tau_i) / this, clipped; the scene clock is the newest batch time.
    age_full_s: Annotated[float, Field(gt=0.0, le=1e9)] = 600.0
    # Confirmation: 1 at the fixture confirmation minimum of supporting batches, falling
    # linearly to 0 at this many; 0 for a pinned fixture (confirmed in an earlier session).
    confirmation_batches_full: Annotated[int, Field(ge=1, le=100_000)] = 12

    @property
    def weights(self) -> tuple[float, float, float, float, float, float]:
        """w of equation (4), in the paper's order."""
        return (
            self.weight_existence,
            self.weight_class,
            self.weight_parent,
            self.weight_position,
            self.weight_age,
            self.weight_confirmation,
        )

    def __post_init__(self) -> None:
        if abs(sum(self.weights) - 1.0) > 1e-9:
            raise ValueError("the six weights of equation (4) must sum to 1")


@dataclass(frozen=True)
class PlannerParams:
    """Target selection (equation (5)) and inspection views (equation (6)), section 3.4."""

    __pydantic_config__ = _CHECKED
    # Equation (5): argmax 0.8 u_i + 0.2 Prox(i), Prox(i) = clip(1 - d_i / 8 m, 0, 1) with d_i
    # the planar distance from the robot to the fixture's center (ours: the paper says "a
    # clipped proximity score that decreases to zero over 8 m").
    uncertainty_weight: Fraction = 0.8
    proximity_weight: Fraction = 0.2
    proximity_range_m: PositiveMetres = 8.0
    # Ties of equation (5) (ours): by fixture id (None), or, with a seed, by a hash of the seed
    # and the id: a reproducible random order. The paired acquisition experiment's random
    # order is weights 0, 0 with a seed; its FIFO order weights 0, 0 without one (track ids
    # are given in the order fixtures were first hypothesised).
    tie_break_seed: Annotated[int, Field(ge=0, le=2**31)] | None = None
    # Equation (6): J = |d_foot - d_pref| + 0.08 D_t + (-0.20) min(Clr, 1 m) + 4 (1 - Cov)
    #                   + P_margin.
    preferred_standoff_m: PositiveMetres = 0.90  # d_pref
    travel_weight: Weight = 0.08
    clearance_weight: Weight = 0.20
    clearance_cap_m: PositiveMetres = 1.0
    coverage_weight: Weight = 4.0
    # P_margin (ours; the paper names it only): this weight times how far the support's
    # farthest corner intrudes into the image margin, as a share of the margin (0 when every
    # corner is inside the margin, the full weight at the border or beyond).
    margin_penalty_weight: Weight = 1.0
    # Standoff: the view's planar distance to the support footprint (ours, around d_pref).
    min_standoff_m: Metres = 0.40
    max_standoff_m: PositiveMetres = 1.60
    # The robot: its radius inflates the map's occupied cells (reachability and view cells).
    robot_radius_m: Metres = 0.25
    # The camera of the inspection view (a Kinect-class sensor on a head at 1.3 m): its
    # horizontal and vertical field of view, range, and the tilt range of the head; the view
    # looks at the support's center, its tilt clipped to the range.
    camera_height_m: PositiveMetres = 1.3
    horizontal_fov_deg: Annotated[float, Field(gt=1.0, lt=180.0)] = 62.0
    vertical_fov_deg: Annotated[float, Field(gt=1.0, lt=180.0)] = 49.0
    min_view_range_m: Metres = 0.3
    max_view_range_m: PositiveMetres = 4.0
    min_pitch_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = -60.0
    max_pitch_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = 10.0
    # Image margin: the share of the half-image at each border a support point must stay clear
    # of to count as covered; the support's center must too (the image-margin constraint).
    image_margin: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.05
    # Projected coverage Cov: the share of an n x n grid of points on the support's top that
    # are in front, in range, inside the image minus the margin and in line of sight; a view
    # needs at least `min_coverage`.
    support_samples_per_axis: Annotated[int, Field(ge=1, le=16)] = 4
    min_coverage: Fraction = 0.5
    # Line of sight on the map: occupied cells block it, except the fixture's own footprint
    # grown by this (the fixture is itself occupied).
    own_footprint_margin_m: Metres = 0.10
    # Travel distance D_t: Dijkstra over 8-connected traversable cells of a grid this many
    # map cells wide (2: 10 cm), a cell traversable when all its map cells are known free and
    # farther than the robot radius from an occupied cell. Views are evaluated at its cells.
    travel_cell_factor: Annotated[int, Field(ge=1, le=8)] = 2
    # At most this many candidate views per fixture (a deterministic stride over the ring).
    max_candidate_views: Annotated[int, Field(ge=1, le=100_000)] = 400
    # A candidate within this of a view that failed for the fixture is excluded.
    failed_view_radius_m: Metres = 0.30
    # Retry cooldown (ours): a fixture whose capture failed waits until this many other targets
    # have been locked, unless nothing else is left to do (no feasible target, no frontier).
    retry_cooldown_locks: Annotated[int, Field(ge=0, le=1000)] = 1
    # Frontiers (Yamauchi): 8-connected clusters of free cells bordering unknown ones, of at
    # least this many cells (0.25 m of frontier at 5 cm); the goal is the reachable frontier
    # nearest by travel, at least `min_frontier_travel_m` away (the robot has seen what is
    # around its feet), at its reachable cell nearest the cluster's centroid.
    min_frontier_cells: Annotated[int, Field(ge=1, le=1_000_000)] = 5
    min_frontier_travel_m: Metres = 0.30

    def __post_init__(self) -> None:
        if self.min_standoff_m >= self.max_standoff_m:
            raise ValueError("min_standoff_m must be below max_standoff_m")
        if self.min_view_range_m >= self.max_view_range_m:
            raise ValueError("min_view_range_m must be below max_view_range_m")
        if self.min_pitch_deg > self.max_pitch_deg:
            raise ValueError("min_pitch_deg must not exceed max_pitch_deg")


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
    occupancy: OccupancyParams = field(default_factory=OccupancyParams)
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)
    planner: PlannerParams = field(default_factory=PlannerParams)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (tuples become lists)."""
        result: dict[str, Any] = _jsonable(asdict(self))
        return result

    @classmethod
    def from_dict(cls, overrides: Mapping[str, Any] | None = None) -> Params:
        """The defaults deep-merged with a (possibly partial) nested dict, then validated.

        InvalidParams names the first offending field (`params.visibility.depth_window_px`).
        """
        check_shape(overrides or {})
        return _validated(orjson.dumps(overrides or {}, option=orjson.OPT_SORT_KEYS))

    @classmethod
    def recorded(cls, params: Mapping[str, Any]) -> Params:
        """The parameters a scene's log recorded, for a replay: as `from_dict`, except that a
        work budget recorded before its range was tightened is clamped to today's ceiling (the
        events decided with it stand; only the scene's batches still to come see the ceiling)."""
        return cls.from_dict(_within_work_ceilings(params))


def _within_work_ceilings(params: Mapping[str, Any]) -> Mapping[str, Any]:
    fixtures = params.get("fixtures")
    if not isinstance(fixtures, Mapping):
        return params
    classes = fixtures.get("taxonomy")
    width = len(classes) if isinstance(classes, list | tuple) and classes else 1
    ceilings = {
        "max_voxels_per_batch": min(1_000_000, MAX_CLASS_SCORE_CELLS // width),
        "max_points_per_batch": 10_000_000,
    }
    clamped = {
        name: min(fixtures[name], ceiling)
        for name, ceiling in ceilings.items()
        if isinstance(fixtures.get(name), int) and fixtures[name] > ceiling
    }
    return {**params, "fixtures": {**fixtures, **clamped}} if clamped else params


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
