"""Exact comparisons of fixture proposals and voxel clusters (floats included)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.fixtures import (
    FixtureProposal,
)
from core.local_clusters import Clusters


def same_proposals(a: Sequence[FixtureProposal], b: Sequence[FixtureProposal]) -> None:
    """Field by field, exactly (floats included)."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert x.label == y.label
        assert x.center.dtype == y.center.dtype and np.array_equal(x.center, y.center)
        assert x.extent.dtype == y.extent.dtype and np.array_equal(x.extent, y.extent)
        assert (x.voxel_count, x.margin, x.mean_score) == (y.voxel_count, y.margin, y.mean_score)
        assert (x.contributed, x.best_frame, x.class_means) == (
            y.contributed,
            y.best_frame,
            y.class_means,
        )


def same_clusters(a: Clusters, b: Clusters) -> None:
    """Per voxel and per cluster, exactly."""
    assert np.array_equal(a.kept, b.kept)
    assert np.array_equal(a.core, b.core)
    assert np.array_equal(a.cluster, b.cluster)
    assert sorted(a.summaries) == sorted(b.summaries)
    for name, summary in a.summaries.items():
        other = b.summaries[name]
        assert summary.class_index == other.class_index
        assert np.array_equal(summary.low, other.low) and np.array_equal(summary.high, other.high)
        assert (summary.proposal is None) == (other.proposal is None)
        if summary.proposal is not None and other.proposal is not None:
            same_proposals([summary.proposal], [other.proposal])
