"""The runner: PBD-AG in process and through the HTTP API agree; every method runs on a stream."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.events import TrackConfirmed
from evaluation.evaluate import WireBatch, run_in_process, run_via_service
from evaluation.methods import DYNAMIC_METHODS, MethodUnavailable, method_named
from evaluation.protocols import FRAMES_PER_BATCH, acquired_truth
from service.app import create_app
from service.bootstrap import build_container
from service.settings import Settings
from sim.scenario import load_scenario
from sim.stream import SimRun, simulate, wire_batches
from tests.clients import local_pbdag_client

HOTEL = Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "hotel-suite.yaml"


@pytest.fixture(scope="module")
def short_stream() -> tuple[SimRun, list[WireBatch]]:
    """The hotel suite squeezed into 16 frames, simulated once for the module."""
    run = simulate(load_scenario(HOTEL, {"frames": 16}), seed=7)
    return run, wire_batches(run, FRAMES_PER_BATCH)


def test_in_process_and_via_service_give_the_same_events_and_graphs(
    tmp_path: Path, short_stream: tuple[SimRun, list[WireBatch]]
) -> None:
    _run, batches = short_stream
    pbdag = method_named("PBD-AG (extended)")
    local = run_in_process(pbdag, batches)
    container = build_container(Settings(data_dir=tmp_path, allow_anonymous_local=True))
    with local_pbdag_client(create_app(container, run_worker=True)) as client:
        remote = run_via_service(pbdag, batches, client)
    assert local.events and local.events == remote.events  # the typed events themselves
    assert all(e.event is not None and e.kind is type(e.event) for e in remote.events)
    assert local.predictions == remote.predictions
    assert any(e.kind is TrackConfirmed for e in local.events)


def test_every_available_method_runs_and_the_truth_starts_at_first_detection(
    short_stream: tuple[SimRun, list[WireBatch]],
) -> None:
    run, batches = short_stream
    for method in DYNAMIC_METHODS:
        if method.unavailable_reason() is not None:
            with pytest.raises(MethodUnavailable):
                run_in_process(method, batches)
            continue
        result = run_in_process(method, batches)
        assert len(result.predictions) == batches[-1][0] + 1, method.name
    truth = acquired_truth(run)
    first: dict[str, int] = {}
    for frame_truth, sim_frame in zip(truth, run.frames, strict=True):
        for listed, real in zip(frame_truth.objects, sim_frame.truth.objects, strict=True):
            assert not listed.present or real.present
            if listed.present:
                first.setdefault(listed.object_id, frame_truth.frame_index)
    assert first  # the short hotel run detects objects
    for object_id, frame in first.items():
        detected = [
            f.frame_index
            for f in run.frames
            if any(d.object_id == object_id and d.kind == "object" for d in f.detections)
        ]
        assert detected and detected[0] <= frame  # acquired at its first detection (or later,
        # when it was absent then)


def test_dynamem_runs_once_the_core_counts_misses_only_on_free_space(
    short_stream: tuple[SimRun, list[WireBatch]],
) -> None:
    """DynaMem-inspired runs on the core's UpdateRules(miss_evidence="free_space")."""
    dynamem = method_named("DynaMem-inspired")
    assert dynamem.unavailable_reason() is None
    assert dynamem.rules.miss_evidence == "free_space"
    _run, batches = short_stream
    result = run_in_process(dynamem, batches)
    assert len(result.predictions) == batches[-1][0] + 1
