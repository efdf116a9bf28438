"""A scenario turned into a stream of posed depth frames, detections and ground truth.

The one render+detect loop of the project: the evaluation reads its batches from `simulate` and
`wire_batches`, the robot (and so the demo) posts the batches of `iter_frames` and
`iter_wire_batches`, so a (scenario, seed) pair gives the same observations either way.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from sim.camera import CameraModel
from sim.detector import SimDetection
from sim.detector_model import RealisticDetector
from sim.observability import observable_frames
from sim.recorded import RecordedSequence, composite, load_recorded
from sim.render import add_kinect_noise, render
from sim.scenario import Scenario, load_scenario, scenario_from_dict
from sim.timeline import Timeline
from sim.trajectory import trajectory_poses
from sim.truth import FrameTruth, ScheduledEvent, TruthFixture, TruthObject
from sim.wire import make_batch, make_frame


@dataclass(frozen=True, eq=False)
class SimFrame:
    """One posed depth frame with its detections and the truth behind it."""

    frame_index: int
    timestamp: float
    camera: CameraModel
    pose: np.ndarray  # (4, 4) camera-to-world, scenario frame
    depth: np.ndarray  # float32 (H, W) metres, 0 = no return
    detections: tuple[SimDetection, ...]
    truth: FrameTruth


@dataclass(frozen=True, eq=False)
class SimRun:
    """A whole simulated run of one scenario under one seed."""

    scenario: Scenario
    seed: int
    frames: tuple[SimFrame, ...]
    fixtures: tuple[TruthFixture, ...]
    events: tuple[ScheduledEvent, ...]
    scenario_sha256: str
    # Per event: the first frame the change could be seen (sim.observability), None if never.
    observable_frames: tuple[int | None, ...] = ()


@dataclass(frozen=True, eq=False)
class FrameSource:
    """Camera, poses and (recorded mode) real depth of a scenario, before any object is drawn."""

    camera: CameraModel
    poses: list[np.ndarray]
    recording: RecordedSequence | None


def frame_source(scenario: Scenario) -> FrameSource:
    """Synthetic poses from the trajectory, or the recording's transformed real poses."""
    spec = scenario.camera
    if scenario.background is not None:
        recording = load_recorded(
            scenario.background.path, scenario.background.frames, spec.min_depth, spec.max_depth
        )
        return FrameSource(recording.camera, list(recording.poses), recording)
    assert scenario.trajectory is not None  # the loader demands one without a background
    poses = trajectory_poses(scenario.trajectory, scenario.frames, spec.eye_height)
    return FrameSource(spec.model(), poses, None)


def run_rng(scenario: Scenario, seed: int) -> np.random.Generator:
    """The single generator behind a run: a (scenario seed, run seed) pair fixes the stream."""
    return np.random.default_rng([scenario.seed, seed])


def iter_frames(scenario: Scenario, seed: int, *, progress: bool = False) -> Iterator[SimFrame]:
    """Simulate frame after frame; memory stays flat, unlike holding a whole `SimRun`."""
    timeline, source, rng = Timeline(scenario), frame_source(scenario), run_rng(scenario, seed)
    settings = scenario.detector
    detector = RealisticDetector(scenario, rng)
    indices = range(scenario.frames)
    for frame_index in tqdm(indices, desc=scenario.name, disable=not progress):
        world, pose = timeline.world(frame_index), source.poses[frame_index]
        view = render(world, source.camera, pose)
        virtual_pixels = None
        if source.recording is not None:
            view, virtual_pixels = composite(view, source.recording.depth(frame_index))
        truth = timeline.truth(frame_index, view.instance)
        detections = detector.detect(view, world, frame_index, rng)
        depth = view.depth
        if settings.depth_noise == "kinect":
            noisy = add_kinect_noise(depth, rng)
            # Real depth already carries its sensor's noise; only the virtual boxes get ours.
            depth = noisy if virtual_pixels is None else np.where(virtual_pixels, noisy, depth)
        yield SimFrame(
            frame_index=frame_index,
            timestamp=frame_index * scenario.frame_period,
            camera=source.camera,
            pose=pose,
            depth=depth,
            detections=tuple(detections),
            truth=truth,
        )


def simulate(scenario: Scenario, seed: int, *, progress: bool = False) -> SimRun:
    """The whole run in memory (about 1 MB of depth and masks per 640 x 480 frame)."""
    timeline, source = Timeline(scenario), frame_source(scenario)
    frames = tuple(iter_frames(scenario, seed, progress=progress))
    observable = observable_frames(
        scenario,
        frames,
        timeline.events,
        source.camera,
        source.poses,
        None if source.recording is None else source.recording.depth,
    )
    return SimRun(
        scenario,
        seed,
        frames,
        timeline.fixture_truths(),
        timeline.events,
        scenario.sha256,
        observable,
    )


def frame_id(scenario: Scenario, seed: int, frame_index: int) -> str:
    """Wire frame id: unique per scenario, seed and frame."""
    return f"{scenario.name}-s{seed}-f{frame_index:05d}"


def iter_wire_batches(
    scenario: Scenario,
    seed: int,
    frames: Iterable[SimFrame],
    frames_per_batch: int = 2,
    depth_encoding: str = "png16",
) -> Iterator[tuple[int, dict[str, Any]]]:
    """Consecutive frames grouped into wire batches as they arrive, each with its last frame index.

    Frames are consumed lazily, so the robot holds one batch in memory, not the whole run.
    """
    if frames_per_batch < 1:
        raise ValueError("frames_per_batch must be at least 1")
    remaining = iter(frames)
    for batch_index in itertools.count():
        chunk = list(itertools.islice(remaining, frames_per_batch))
        if not chunk:
            return
        encoded = [
            make_frame(
                frame_id(scenario, seed, frame.frame_index),
                frame.timestamp,
                frame.camera,
                frame.pose,
                frame.depth,
                frame.detections,
                depth_encoding,
            )
            for frame in chunk
        ]
        batch_id = f"{scenario.name}-s{seed}-b{batch_index:05d}"
        yield chunk[-1].frame_index, make_batch(batch_id, encoded)


def wire_batches(
    run: SimRun, frames_per_batch: int = 2, depth_encoding: str = "png16"
) -> list[tuple[int, dict[str, Any]]]:
    """A whole run's wire batches, each with the index of its last frame (the evaluation's)."""
    return list(
        iter_wire_batches(run.scenario, run.seed, run.frames, frames_per_batch, depth_encoding)
    )


RUN_FORMAT = 2  # 2: observable frames of the events


def _detection_record(detection: SimDetection, mask_index: int) -> dict[str, Any]:
    """A detection as JSON; its mask lives in the npz file at `mask_index`."""
    return {
        "object_id": detection.object_id,
        "label": detection.label,
        "score": detection.score,
        "kind": detection.kind,
        "mask_index": mask_index,
        "embedding": None if detection.embedding is None else detection.embedding.tolist(),
        "class_scores": detection.class_scores,
    }


def _detection_from_record(record: dict[str, Any], mask: np.ndarray) -> SimDetection:
    """Inverse of `_detection_record`."""
    embedding = record["embedding"]
    return SimDetection(
        object_id=record["object_id"],
        label=record["label"],
        score=record["score"],
        mask=mask,
        embedding=None if embedding is None else np.asarray(embedding, dtype=np.float64),
        kind=record["kind"],
        class_scores=record["class_scores"],
    )


def save_run(run: SimRun, folder: str | Path) -> None:
    """Cache a run: depth maps and packed masks in depth.npz, everything else in run.json."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    masks = [detection.mask for frame in run.frames for detection in frame.detections]
    shape = run.frames[0].depth.shape if run.frames else (0, 0)
    packed = (
        np.packbits(np.reshape(masks, (len(masks), -1)), axis=1)
        if masks
        else np.zeros((0, 0), np.uint8)
    )
    # Uncompressed: float32 sensor noise barely compresses and compression costs seconds.
    np.savez(
        folder / "depth.npz",
        depth=np.stack([frame.depth for frame in run.frames]),
        masks=packed,
        mask_shape=np.array(shape),
    )
    next_mask = iter(range(len(masks)))
    record = {
        "format": RUN_FORMAT,
        "scenario": dict(run.scenario.raw),
        "scenario_source": None if run.scenario.source is None else str(run.scenario.source),
        "scenario_sha256": run.scenario_sha256,
        "seed": run.seed,
        "fixtures": [dataclasses.asdict(fixture) for fixture in run.fixtures],
        "events": [dataclasses.asdict(event) for event in run.events],
        "observable_frames": list(run.observable_frames),
        "frames": [
            {
                "frame_index": frame.frame_index,
                "timestamp": frame.timestamp,
                "camera": dataclasses.asdict(frame.camera),
                "pose": frame.pose.tolist(),
                "detections": [
                    _detection_record(detection, next(next_mask)) for detection in frame.detections
                ],
                "truth": [dataclasses.asdict(item) for item in frame.truth.objects],
            }
            for frame in run.frames
        ],
    }
    (folder / "run.json").write_text(json.dumps(record), encoding="utf-8")


def _vec3(values: list[float]) -> tuple[float, float, float]:
    """A JSON list back to the truth's float triple."""
    x, y, z = values
    return (x, y, z)


def load_run(folder: str | Path) -> SimRun:
    """A run cached by `save_run`."""
    folder = Path(folder)
    record = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    if record.get("format") != RUN_FORMAT:
        raise ValueError(f"{folder}: run cache format {record.get('format')!r}, need {RUN_FORMAT}")
    source = record["scenario_source"]
    scenario = scenario_from_dict(record["scenario"], None if source is None else Path(source))
    with np.load(folder / "depth.npz") as archive:
        depths, packed, shape = archive["depth"], archive["masks"], tuple(archive["mask_shape"])
    pixels = int(np.prod(shape))

    def mask(index: int) -> np.ndarray:
        """One stored mask, unpacked."""
        return np.unpackbits(packed[index], count=pixels).astype(bool).reshape(shape)

    frames = tuple(
        SimFrame(
            frame_index=item["frame_index"],
            timestamp=item["timestamp"],
            camera=CameraModel(**item["camera"]),
            pose=np.asarray(item["pose"], dtype=np.float64),
            depth=depths[position],
            detections=tuple(
                _detection_from_record(entry, mask(entry["mask_index"]))
                for entry in item["detections"]
            ),
            truth=FrameTruth(
                item["frame_index"],
                tuple(
                    TruthObject(**{**entry, "center": _vec3(entry["center"])})
                    for entry in item["truth"]
                ),
            ),
        )
        for position, item in enumerate(record["frames"])
    )
    fixtures = tuple(
        TruthFixture(**{**entry, "center": _vec3(entry["center"]), "size": _vec3(entry["size"])})
        for entry in record["fixtures"]
    )
    events = tuple(ScheduledEvent(**entry) for entry in record["events"])
    return SimRun(
        scenario,
        record["seed"],
        frames,
        fixtures,
        events,
        record["scenario_sha256"],
        tuple(record["observable_frames"]),
    )


def main(argv: list[str] | None = None) -> None:
    """Simulate a scenario and print its timing and detection counts."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=None, help="shorten the run to N frames")
    parser.add_argument("--save", type=Path, default=None, help="cache the run in this folder")
    arguments = parser.parse_args(argv)
    scenario = load_scenario(arguments.scenario, frames=arguments.frames)
    started = time.perf_counter()
    run = simulate(scenario, arguments.seed, progress=True)
    elapsed = time.perf_counter() - started
    detections = sum(len(frame.detections) for frame in run.frames)
    print(
        f"{scenario.name}: {len(run.frames)} frames in {elapsed:.1f} s "
        f"({1000 * elapsed / len(run.frames):.0f} ms/frame), {detections} detections"
    )
    if arguments.save is not None:
        save_run(run, arguments.save)


if __name__ == "__main__":
    main()
