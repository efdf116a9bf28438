"""Detector plugins: a frame in, a list of detections (label, score, mask) out.

A plugin is registered under the entry-point group `pbdag.detectors`; the entry point names a
factory (usually the class) called with the detector options as a mapping of strings (the
command line's `--labels`, `--masks`, `--label-topic`, and every `--detector-option KEY=VALUE`).
What it returns follows `Detector`. Two plugins ship: `label-image` (masks from an instance-label
image topic of a bag) and `instance-pngs` (masks from a folder of per-frame instance PNGs).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np
import numpy.typing as npt
import yaml

from ingest.checks import (
    BadFile,
    bad_file_error,
    frame_error,
    library_reason,
    open_png,
    outside_problem,
)
from ingest.frames import FrameSource, IngestError, SkipFrame, SourceFrame
from ingest.messages import image_array

ENTRY_POINT_GROUP = "pbdag.detectors"
INSTANCE_MODES = frozenset({"L", "P", "I", "I;16", "I;16B"})
MAX_LABEL_MAP_BYTES = 10 * 2**20  # a label map names classes: a few kilobytes
INSTANCE_PNG_FIX = "write the frame's single-channel instance PNG there, or delete it"
Kind = Literal["object", "fixture"]
logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Detection:
    """One instance in a frame: a boolean mask the size of the depth image."""

    label: str
    score: float
    mask: npt.NDArray[np.bool_]
    kind: Kind = "object"  # "fixture" for furniture and structure
    embedding: Sequence[float] | None = None


class Detector(Protocol):
    """What a detector plugin provides.

    `topics`: bag topics the detector reads (each frame then carries the message of each topic
    nearest to its stamp in `frame.messages`; a frame without one is skipped). Empty for
    detectors that read files or run a model on the frame itself.

    `detect`: the detections of one frame. `source` is the recording the frame comes from (its
    path, name...). Raise `SkipFrame(reason)` when the frame has no usable detections at all
    (for example no label image): such a frame is not sent, because a frame sent with no
    detections tells the service that nothing is in view.
    """

    topics: tuple[str, ...]

    def detect(self, frame: SourceFrame, source: FrameSource) -> list[Detection]:
        """The detections of one frame."""
        ...


DetectorFactory = Callable[[Mapping[str, str]], Detector]


def available_detectors() -> dict[str, Any]:
    """The installed detector plugins by name (entry points, not yet loaded)."""
    return {entry.name: entry for entry in entry_points(group=ENTRY_POINT_GROUP)}


def load_detector(name: str, options: Mapping[str, str]) -> Detector:
    """Build the detector plugin `name` with `options`; unknown names list the installed ones."""
    found = available_detectors()
    if name not in found:
        raise IngestError(
            f"unknown detector {name!r}; installed detectors ({ENTRY_POINT_GROUP} entry points): "
            f"{', '.join(sorted(found)) or 'none'}"
        )
    factory: DetectorFactory = found[name].load()
    detector = factory(options)
    if not callable(getattr(detector, "detect", None)):
        raise IngestError(f"detector {name!r} has no detect(frame, source) method")
    topics = getattr(detector, "topics", None)
    if not isinstance(topics, tuple) or not all(isinstance(t, str) for t in topics):
        raise IngestError(
            f"detector {name!r} must have `topics`, a tuple of bag topic names (empty for none)"
        )
    return detector


def required_option(options: Mapping[str, str], name: str, detector: str) -> str:
    """An option the detector cannot do without, with a message naming the flag."""
    value = options.get(name)
    if not value:
        raise IngestError(f"detector {detector!r} needs --{name}")
    return value


@dataclass(frozen=True)
class LabelEntry:
    """What an instance id stands for."""

    label: str
    kind: Kind = "object"
    score: float = 1.0


def load_label_map(path: Path) -> dict[int, LabelEntry]:
    """An id -> class map from JSON or YAML.

    Each value is a class name (an object) or a mapping with `label` and optionally
    `kind` (`object` or `fixture`) and `score` (0 to 1), e.g. `{"3": {"label": "table",
    "kind": "fixture"}}`.
    """
    if not path.is_file():
        raise IngestError(f"label map {path} does not exist")
    with path.open("rb") as file:
        data = file.read(MAX_LABEL_MAP_BYTES + 1)
    if len(data) > MAX_LABEL_MAP_BYTES:
        raise IngestError(f"label map {path} is larger than {MAX_LABEL_MAP_BYTES} bytes")
    try:
        text = data.decode("utf-8")
        raw = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except UnicodeDecodeError as error:
        raise IngestError(f"label map {path} is not UTF-8 text") from error
    except (json.JSONDecodeError, yaml.YAMLError) as error:
        raise IngestError(f"label map {path} cannot be parsed ({_parse_problem(error)})") from error
    if not isinstance(raw, dict) or not raw:
        raise IngestError(f"label map {path} must be a non-empty mapping of id -> class name")
    entries = {}
    for key, value in raw.items():
        try:
            instance_id = int(key)
        except (TypeError, ValueError):
            raise IngestError(f"label map {path}: key {key!r} is not an integer id") from None
        if instance_id <= 0:
            raise IngestError(
                f"label map {path}: id {instance_id} must be positive (0 is background)"
            )
        entries[instance_id] = _label_entry(value, f"label map {path}: id {instance_id}")
    return entries


def _parse_problem(error: json.JSONDecodeError | yaml.YAMLError) -> str:
    """Where and why a label map does not parse, without the quoted lines YAML adds."""
    problem, mark = getattr(error, "problem", None), getattr(error, "problem_mark", None)
    if problem and mark is not None:
        return f"line {mark.line + 1}, column {mark.column + 1}: {problem}"
    return library_reason(error)


def _label_entry(value: object, where: str) -> LabelEntry:
    """One label map value: a name, or a mapping with label, kind and score."""
    if isinstance(value, str) and value.strip():
        return LabelEntry(value.strip())
    if not isinstance(value, dict) or not isinstance(value.get("label"), str):
        raise IngestError(f"{where}: expected a class name or a mapping with a 'label'")
    unknown = set(value) - {"label", "kind", "score"}
    if unknown:
        raise IngestError(f"{where}: unknown keys {sorted(unknown)} (label, kind, score)")
    kind = value.get("kind", "object")
    if kind not in ("object", "fixture"):
        raise IngestError(f"{where}: kind must be 'object' or 'fixture', got {kind!r}")
    score = value.get("score", 1.0)
    if isinstance(score, bool) or not isinstance(score, int | float) or not 0 <= score <= 1:
        raise IngestError(f"{where}: score must be a number in [0, 1], got {score!r}")
    return LabelEntry(value["label"], kind, float(score))


class InstanceMasks:
    """Instance-id image -> one detection per labelled id (shared by both shipped plugins)."""

    def __init__(self, options: Mapping[str, str], detector: str) -> None:
        self.detector = detector
        self.label_map = load_label_map(Path(required_option(options, "labels", detector)))
        try:
            self.min_pixels = int(options.get("min-pixels", "50"))
        except ValueError:
            raise IngestError("--detector-option min-pixels must be an integer") from None
        self.unlabelled: set[int] = set()

    def detections(
        self, instances: npt.NDArray[Any], frame: SourceFrame, where: str
    ) -> list[Detection]:
        """The mask of every labelled id in `instances` (0 is background)."""
        expected = (frame.intrinsics.height, frame.intrinsics.width)
        if instances.shape != expected:
            raise IngestError(
                f"{where}: instance image is {instances.shape[1]}x{instances.shape[0]}, the depth "
                f"is {expected[1]}x{expected[0]}"
            )
        found = []
        for instance_id in np.unique(instances):
            if instance_id == 0:
                continue
            entry = self.label_map.get(int(instance_id))
            if entry is None:
                if int(instance_id) not in self.unlabelled:
                    self.unlabelled.add(int(instance_id))
                    logger.warning("%s: instance id %d is not in the label map", where, instance_id)
                continue
            mask = instances == instance_id
            if int(mask.sum()) < self.min_pixels:
                continue
            found.append(Detection(entry.label, entry.score, mask, entry.kind))
        return found


class LabelImageDetector:
    """Masks from a `sensor_msgs/Image` instance-label topic (one integer id per instance, 0 the
    background), with a label map. Options: `label-topic`, `labels`, `min-pixels` (default 50)."""

    def __init__(self, options: Mapping[str, str]) -> None:
        self.topic = required_option(options, "label-topic", "label-image")
        self.topics = (self.topic,)
        self.masks = InstanceMasks(options, "label-image")

    def detect(self, frame: SourceFrame, source: FrameSource) -> list[Detection]:
        """The labelled instances of the label image synchronised to the frame."""
        message = frame.messages.get(self.topic)
        if message is None:
            raise SkipFrame(f"no {self.topic} message near the depth stamp")
        instances = image_array(message, self.topic)
        if instances.dtype.kind == "f":
            raise IngestError(f"topic {self.topic}: label images must hold integer ids")
        return self.masks.detections(instances, frame, f"topic {self.topic}")


class InstancePngsDetector:
    """Masks from a folder of per-frame instance PNGs (one integer id per pixel, 0 the
    background), with a label map.

    Options: `masks` (the folder), `labels`, `pattern` (the file name of a frame's PNG, a Python
    format string over `frame_id`, `index` and `stamp`; default `{frame_id}.png`, for bags e.g.
    `{index:06d}.png`), `min-pixels` (default 50). A frame without its PNG is skipped.
    """

    topics: tuple[str, ...] = ()

    def __init__(self, options: Mapping[str, str]) -> None:
        self.folder = Path(required_option(options, "masks", "instance-pngs"))
        if not self.folder.is_dir():
            raise IngestError(f"instance PNG folder {self.folder} does not exist")
        self.pattern = options.get("pattern", "{frame_id}.png")
        self.masks = InstanceMasks(options, "instance-pngs")

    def detect(self, frame: SourceFrame, source: FrameSource) -> list[Detection]:
        """The labelled instances of the frame's PNG."""
        try:
            name = self.pattern.format(
                frame_id=frame.frame_id, index=frame.index, stamp=frame.stamp_ns
            )
        except (KeyError, IndexError, ValueError) as error:
            raise IngestError(f"--detector-option pattern={self.pattern!r}: {error}") from error
        path = self.folder / name
        label = f"frame {frame.index}"
        outside = outside_problem(path, self.folder)
        if outside is not None:
            fix = f"copy the file into {self.folder} instead of linking to it"
            raise frame_error(label, path, outside, fix)
        if not path.is_file():
            raise SkipFrame("no instance PNG")
        try:
            with open_png(path) as image:
                if image.mode not in INSTANCE_MODES:
                    raise BadFile(f"is not single-channel (Pillow mode {image.mode})")
                instances = np.asarray(image)
        except BadFile as bad:
            raise bad_file_error(label, path, bad, INSTANCE_PNG_FIX) from bad
        except Exception as error:  # Pillow reports corrupt data through many types
            problem = f"is truncated or corrupt ({type(error).__name__})"
            raise frame_error(label, path, problem, INSTANCE_PNG_FIX) from error
        return self.masks.detections(instances, frame, str(path))
