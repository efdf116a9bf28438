"""The fixture clusters kept between batches equal the whole map clustered anew (section 3.2)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from core.fixture_association import (
    FixtureTrackView,
    absorbs,
    associate_fixtures,
    eligible_distance,
)
from core.fixture_map import VoxelMap, full_clusters, neighbour_offsets
from core.fixtures import (
    FixtureProposal,
    VoxelEvidence,
    fixture_proposals,
    kept_voxels,
    merged_voxels,
)
from core.masks import Mask
from core.params import FixtureParams
from core.voxels import pack
from tests.core.cluster_checks import same_clusters, same_proposals

# Scores of a mask over three classes: clearly one class, two classes too close to call (its
# voxels drop out), or below every threshold; masks of all kinds over the same voxels move
# them in and out of clusters.
SCORES = (
    (0.7, 0.2, 0.1),
    (0.2, 0.7, 0.1),
    (0.1, 0.2, 0.8),
    (0.45, 0.44, 0.1),
    (0.1, 0.1, 0.1),
    (0.9, 0.0, 0.0),
)


def blob(rng: np.random.Generator, span: int) -> np.ndarray:
    """Packed keys of a random box of voxels with holes: a lump, or a long thin bar (whose
    cluster a batch at one end renames, and whose far borders then change hands)."""
    low = rng.integers(0, span, size=3)
    size = rng.integers(1, 6, size=3)
    if rng.random() < 0.3:
        size[rng.integers(0, 3)] = rng.integers(span // 2, span + 1)
    axes = [np.arange(low[i], low[i] + size[i]) for i in range(3)]
    voxels = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    voxels = voxels[rng.random(len(voxels)) < 0.8]
    return np.unique(pack(voxels.astype(np.int64)))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    eps_voxels=st.sampled_from([0.8, 1.2, 1.5, 1.8]),
    min_points=st.integers(1, 8),
    span=st.sampled_from([4, 8, 14]),
    batches=st.integers(1, 8),
)
def test_kept_clusters_equal_the_full_reclustering(
    seed: int, eps_voxels: float, min_points: int, span: int, batches: int
) -> None:
    rng = np.random.default_rng(seed)
    params = FixtureParams(
        taxonomy=("table", "desk", "shelf"),
        voxel_size_m=0.05,
        dbscan_eps_m=0.05 * eps_voxels,
        dbscan_min_points=min_points,
        default_size_limits=(0.0, 0.0, 0.0, 0.4, 0.4, 0.4),  # some clusters too big
        size_limits={},
    )
    assert neighbour_offsets(params) is not None  # the local update is what is tested
    voxel_map = VoxelMap()
    voxel_map.clusters(params)  # built on the empty map, then carried from batch to batch
    for b in range(batches):
        evidence = [
            VoxelEvidence(
                f"f{b}-{rng.integers(0, 2)}", SCORES[rng.integers(0, len(SCORES))], blob(rng, span)
            )
            for _ in range(rng.integers(1, 4))
        ]
        pairs = [(e.voxels, e.class_scores) for e in evidence]
        update = voxel_map.update(params, pairs, None)  # type: ignore[arg-type]
        # The reference: the whole map merged and clustered anew.
        keys, counts, sums = merged_voxels(
            (voxel_map.keys, voxel_map.counts, voxel_map.sums), evidence
        )
        kept, scores, margins = kept_voxels(counts, sums, params)
        expected = fixture_proposals(keys, counts, sums, kept, scores, margins, evidence, params)
        same_proposals(update.proposals(evidence), expected)
        after = update.applied(voxel_map)
        assert np.array_equal(after.keys, keys) and np.array_equal(after.counts, counts)
        assert np.array_equal(after.sums, sums)
        assert after == voxel_map.merged(pairs)
        same_clusters(after.clusters(params), full_clusters(after, params))
        voxel_map = after


def test_parameters_the_offsets_cannot_stand_for_recluster_the_whole_map() -> None:
    offsets = neighbour_offsets(FixtureParams())
    assert offsets is not None and len(offsets) == 27  # the default: 26 neighbours and itself
    assert neighbour_offsets(FixtureParams(dbscan_eps_m=0.1)) is None  # exactly two voxels
    assert neighbour_offsets(FixtureParams(dbscan_eps_m=0.05)) is None  # a rounding error away
    assert neighbour_offsets(FixtureParams(dbscan_eps_m=0.2)) is None  # beyond two voxels


def plane(*cells: tuple[range, range]) -> np.ndarray:
    """Packed keys of rectangles of voxels in the plane z = 0."""
    voxels = [(x, y, 0) for xs, ys in cells for x in xs for y in ys]
    return np.unique(pack(np.array(voxels, dtype=np.int64)))


def test_a_renamed_cluster_hands_a_far_border_voxel_to_an_untouched_cluster() -> None:
    # An L-shaped table cluster D (named by its corner at the origin) and a bar Q beyond it
    # share a border voxel b far from the origin; b belongs to D, the smaller name. A batch
    # that drops D's first voxels renames D past Q, so b changes hands, although Q has no
    # voxel near the batch and keeps most of its voxels outside the re-clustered region.
    params = FixtureParams(
        taxonomy=("table", "desk", "shelf"),
        dbscan_min_points=4,
        default_size_limits=(0.0, 0.0, 0.0, 5.0, 5.0, 5.0),
        size_limits={},
    )
    d = plane((range(0, 26), range(0, 2)), (range(24, 26), range(2, 11)))
    q = plane((range(5, 23), range(12, 14)))
    b = plane((range(23, 24), range(11, 12)))
    table = (0.9, 0.0, 0.0)
    voxel_map = VoxelMap().merged([(np.union1d(np.union1d(d, q), b), table)])
    before = voxel_map.clusters(params)
    at_b = int(np.searchsorted(voxel_map.keys, b[0]))
    assert not before.core[at_b] and before.cluster[at_b] == d[0]  # b is D's border
    evidence = [VoxelEvidence("f1", (0.0, 0.9, 0.0), plane((range(0, 10), range(0, 2))))]
    pairs = [(e.voxels, e.class_scores) for e in evidence]
    update = voxel_map.update(params, pairs, None)  # type: ignore[arg-type]
    after = update.applied(voxel_map)
    clusters = after.clusters(params)
    assert clusters.cluster[int(np.searchsorted(after.keys, b[0]))] == q[0]  # now Q's
    same_clusters(clusters, full_clusters(after, params))
    keys, counts, sums = merged_voxels((voxel_map.keys, voxel_map.counts, voxel_map.sums), evidence)
    kept, scores, margins = kept_voxels(counts, sums, params)
    expected = fixture_proposals(keys, counts, sums, kept, scores, margins, evidence, params)
    same_proposals(update.proposals(evidence), expected)
    assert [p.voxel_count for p in expected] == [q.size + 1, d.size - 20]


@settings(max_examples=100, deadline=None)
@given(
    height=st.integers(1, 40),
    width=st.integers(1, 40),
    stride=st.integers(1, 6),
    density=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_strided_mask_pixels_are_the_mask_pixels_on_the_stride_lattice(
    height: int, width: int, stride: int, density: float, seed: int
) -> None:
    pixels = np.random.default_rng(seed).random((height, width)) < density
    mask = Mask.from_array(pixels)
    rows, columns = np.divmod(mask.flat_indices(), width)
    expected = mask.flat_indices()[(rows % stride == 0) & (columns % stride == 0)]
    got = mask.strided_indices(stride)
    assert got.dtype == expected.dtype and np.array_equal(got, expected)


def associate_one_by_one(
    proposals: Sequence[FixtureProposal], tracks: Sequence[FixtureTrackView], params: FixtureParams
) -> tuple[dict[int, str], dict[int, str]]:
    """The association with every pair tried one by one (no gate found for all pairs at once)."""
    pairs = []
    for j, proposal in enumerate(proposals):
        for track in tracks:
            distance = eligible_distance(track, proposal, params)
            if distance is not None:
                pairs.append((distance, track.track_id, j))
    matches: dict[int, str] = {}
    used: set[str] = set()
    for _distance, track_id, j in sorted(pairs):
        if j not in matches and track_id not in used:
            matches[j] = track_id
            used.add(track_id)
    absorbed: dict[int, str] = {}
    by_id = {track.track_id: track for track in tracks}
    for j, proposal in enumerate(proposals):
        if j in matches:
            continue
        for track_id in sorted(used):
            if absorbs(by_id[track_id], proposal, params):
                absorbed[j] = track_id
                break
    return matches, absorbed


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    proposals=st.integers(0, 30),
    tracks=st.integers(0, 8),
    containment=st.sampled_from([0.0, 0.5, 0.9]),
)
def test_association_gates_pairs_at_once_as_one_by_one(
    seed: int, proposals: int, tracks: int, containment: float
) -> None:
    rng = np.random.default_rng(seed)
    params = FixtureParams(residual_containment=containment)
    labels = ("table", "desk")

    def proposal() -> FixtureProposal:
        label = labels[rng.integers(0, 2)]
        return FixtureProposal(
            label,
            np.round(rng.uniform(0, 4, 3), 2),
            rng.uniform(0.2, 2.0, 3),
            10,
            0.1,
            0.6,
            int(rng.integers(0, 3)),
            None,
            {label: 0.6, "table" if label == "desk" else "desk": float(rng.uniform(0.4, 0.6))},
        )

    found = [proposal() for _ in range(proposals)]
    known = [
        FixtureTrackView(
            f"trk-{k:06d}",
            labels[rng.integers(0, 2)],
            tuple(float(v) for v in np.round(rng.uniform(0, 4, 3), 1)),  # type: ignore[arg-type]
            tuple(float(v) for v in rng.uniform(0.2, 2.0, 3)),  # type: ignore[arg-type]
        )
        for k in range(tracks)
    ]
    assert associate_fixtures(found, known, params) == associate_one_by_one(found, known, params)


def test_with_eps_at_two_voxels_each_batch_reclusters_the_whole_map_alike() -> None:
    params = FixtureParams(
        taxonomy=("table", "desk", "shelf"),
        dbscan_eps_m=0.1,  # exactly two voxels: the offsets cannot stand for the metric test
        dbscan_min_points=3,
        default_size_limits=(0.0, 0.0, 0.0, 0.4, 0.4, 0.4),
        size_limits={},
    )
    rng = np.random.default_rng(5)
    voxel_map = VoxelMap()
    for b in range(6):
        evidence = [
            VoxelEvidence(f"f{b}", SCORES[rng.integers(0, len(SCORES))], blob(rng, 10))
            for _ in range(2)
        ]
        update = voxel_map.update(params, [(e.voxels, e.class_scores) for e in evidence], None)  # type: ignore[arg-type]
        keys, counts, sums = merged_voxels(
            (voxel_map.keys, voxel_map.counts, voxel_map.sums), evidence
        )
        kept, scores, margins = kept_voxels(counts, sums, params)
        expected = fixture_proposals(keys, counts, sums, kept, scores, margins, evidence, params)
        same_proposals(update.proposals(evidence), expected)
        voxel_map = update.applied(voxel_map)
        same_clusters(voxel_map.clusters(params), full_clusters(voxel_map, params))
