"""The runner: PBD-AG in process and through the HTTP API give the same events on one stream."""

from __future__ import annotations

from pathlib import Path

from evaluation.evaluate import run_in_process, run_via_service
from evaluation.methods import DYNAMIC_METHODS, method_named
from evaluation.protocols import FRAMES_PER_BATCH, acquired_truth
from service.app import create_app
from service.bootstrap import build_container
from service.settings import Settings
from sim.scenario import load_scenario
from sim.stream import simulate, wire_batches
from tests.clients import local_client

HOTEL = Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "hotel-suite.yaml"


def short_stream():
    run = simulate(load_scenario(HOTEL, {"frames": 24}), seed=7)
    return run, wire_batches(run, FRAMES_PER_BATCH)


def test_in_process_and_via_service_give_the_same_events_and_graphs(tmp_path):
    _run, batches = short_stream()
    pbdag = method_named("PBD-AG")
    local = run_in_process(pbdag, batches)
    container = build_container(Settings(data_dir=tmp_path, allow_anonymous_local=True))
    with local_client(create_app(container, run_worker=True)) as client:
        remote = run_via_service(pbdag, batches, client)
    key = [(e.frame, e.type, e.track_id, dict(e.details)) for e in local.events]
    assert key and key == [(e.frame, e.type, e.track_id, dict(e.details)) for e in remote.events]
    assert local.predictions == remote.predictions
    assert any(e.type == "confirm" for e in local.events)


def test_every_method_runs_and_the_truth_starts_at_first_sighting():
    run, batches = short_stream()
    for method in DYNAMIC_METHODS:
        result = run_in_process(method, batches)
        assert len(result.predictions) == batches[-1][0] + 1, method.name
    truth = acquired_truth(run, run.scenario.detector.min_visible_pixels)
    for frame_truth, sim_frame in zip(truth, run.frames, strict=True):
        for listed, real in zip(frame_truth.objects, sim_frame.truth.objects, strict=True):
            assert not listed.present or real.present
    first = {}
    for frame_truth in truth:
        for obj in frame_truth.objects:
            if obj.present:
                first.setdefault(obj.object_id, frame_truth.frame_index)
    for object_id, frame in first.items():
        seen = [f.truth.objects for f in run.frames[: frame + 1]]
        assert any(
            o.object_id == object_id
            and o.visible_pixels >= run.scenario.detector.min_visible_pixels
            for objects in seen
            for o in objects
        )
