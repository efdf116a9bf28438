"""On every shipped stream, the fixture step with the clusters kept between batches gives, batch
by batch, exactly what clustering the whole voxel map anew gives (the reference path)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.eval_extra import require_eval_extra

require_eval_extra()  # the streams are rendered by the simulator

from api_schema import BatchIn  # noqa: E402
from codec.observations import decode_batch  # noqa: E402
from core.decide import decide  # noqa: E402
from core.evolve import fold  # noqa: E402
from core.fixture_map import full_clusters  # noqa: E402
from core.fixture_step import FixtureBatch, fixture_batch  # noqa: E402
from core.state import SceneState  # noqa: E402
from sim.scenario import REPO_ROOT, load_scenario  # noqa: E402
from sim.stream import iter_frames, iter_wire_batches  # noqa: E402
from tests.conftest import SHARED_DATA  # noqa: E402
from tests.core.cluster_checks import same_clusters, same_proposals  # noqa: E402

SCENARIOS = REPO_ROOT / "sim" / "scenarios"
STREAMS = sorted(SCENARIOS.glob("*.yaml")) + sorted((SCENARIOS / "active").glob("*.yaml"))
# The active floor's 20-frame passive walk (its rollouts start from it) faces no fixture.
WITHOUT_FIXTURES = {"floor"}
# Each stream squeezed to this many frames (the same story, laps and events scaled): every
# fixture is still seen from several batches, at a third of the full streams' time.
FRAMES = 100


def same_fixture_batch(a: FixtureBatch, b: FixtureBatch) -> None:
    """The evidence event, every cluster's proposal in order, and the association's outcome."""
    assert a.evidence_event == b.evidence_event
    same_proposals(a.proposals, b.proposals)
    assert sorted(a.observed) == sorted(b.observed)
    same_proposals(
        [a.observed[k] for k in sorted(a.observed)], [b.observed[k] for k in sorted(b.observed)]
    )
    same_proposals(a.unexplained, b.unexplained)


def test_the_shipped_streams_are_all_here() -> None:
    names = {path.stem for path in STREAMS}
    assert {"demo", "hotel-suite", "office", "bedroom", "busy-living-room", "kitchen-real"} <= names
    assert {"flat", "floor", "suite"} <= names


@pytest.mark.parametrize("path", STREAMS, ids=lambda path: path.stem)
def test_kept_clusters_equal_the_full_reclustering_on_every_batch(path: Path) -> None:
    if path.stem == "kitchen-real" and not (SHARED_DATA / "7scenes-kitchen").is_dir():
        pytest.skip(f"needs the real sequence in ../shared/data ({SHARED_DATA} lacks it)")
    scenario = load_scenario(path)
    if scenario.frames > FRAMES:
        scenario = load_scenario(path, frames=FRAMES)
    state = SceneState()
    for _last, body in iter_wire_batches(scenario, 0, iter_frames(scenario, 0)):
        batch = decode_batch(BatchIn.model_validate(body))
        expected = fixture_batch(state, batch, state.params, incremental=False)
        got = fixture_batch(state, batch, state.params)
        same_fixture_batch(got, expected)
        state = fold(state, decide(state, batch))
    # The comparison had something to compare (or, for a walk past no fixture, nothing).
    assert (len(state.voxels) == 0) == (path.stem in WITHOUT_FIXTURES)
    # The clusters the folds carried to the last state are those of its map built anew.
    carried = state.voxels.cache.get("clusters")
    assert (carried is None) == (path.stem in WITHOUT_FIXTURES)
    if carried is not None:
        same_clusters(carried, full_clusters(state.voxels, state.params.fixtures))
