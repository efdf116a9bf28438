"""Read frames, detect, build batches, send them: the loop both `pbdag ingest` commands run."""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterator
from dataclasses import dataclass, field

from tqdm import tqdm

from api_schema.requests import FrameIn
from ingest.detectors import Detector
from ingest.frames import FrameSource, SkipFrame
from ingest.sink import SinkResult, post_batches
from ingest.wire import batches, frame_in


@dataclass
class IngestSummary:
    """What an ingest read (every frame the stride and limit selected), skipped (by reason), sent,
    and what the service did with it."""

    frames_read: int = 0
    frames_sent: int = 0
    detections_sent: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    sink: SinkResult | None = None

    def lines(self) -> list[str]:
        """The summary as printed at the end of `pbdag ingest`."""
        skipped_total = sum(self.skipped.values())
        lines = [
            f"frames read: {self.frames_read}, sent: {self.frames_sent} "
            f"(with {self.detections_sent} detections), skipped: {skipped_total}"
        ]
        lines += [f"  skipped {count}: {reason}" for reason, count in sorted(self.skipped.items())]
        if self.sink is None:
            lines.append("nothing sent: no frame could be used")
        else:
            sink = self.sink
            verb = "created" if sink.scene_created else "existing"
            lines.append(
                f"scene {sink.scene_id} ({verb}): batches posted {sink.posted}"
                + (
                    f" ({len(sink.accepted_before)} accepted before)"
                    if sink.accepted_before
                    else ""
                )
                + (
                    f", {sink.busy_retries} requests repeated after a busy reply (429/503)"
                    if sink.busy_retries
                    else ""
                )
            )
            statuses: dict[str, int] = {}
            for status in sink.statuses.values():
                statuses[status] = statuses.get(status, 0) + 1
            lines.append(
                "batch statuses: " + ", ".join(f"{n} {s}" for s, n in sorted(statuses.items()))
            )
            if sink.events_appended is None:
                lines.append("events appended: not waited for (pass --wait)")
            else:
                lines.append(f"events appended: {sink.events_appended}")
            lines += [f"  dead batch {batch}: {error}" for batch, error in sink.errors.items()]
        return lines


def batch_prefix(name: str) -> str:
    """A batch-id prefix from a recording's name (the wire allows letters, digits and ._:-)."""
    return re.sub(r"[^A-Za-z0-9._:-]+", "-", name).strip("-")[:150] or "ingest"


def ingest(
    source: FrameSource,
    detector: Detector | None,
    *,
    url: str,
    scene: str,
    token: str | None = None,
    frames_per_batch: int = 8,
    wait: bool = False,
    prefix: str | None = None,
    progress: bool = True,
) -> IngestSummary:
    """Check every frame of `source`, then send every usable one, with `detector`'s detections,
    to the scene."""
    summary = IngestSummary()
    topics = detector.topics if detector is not None else ()
    # Every frame is checked before the first request: a bad file, pose, intrinsics or image
    # size is reported before the scene is created or a batch is posted.
    source.check(topics)
    bar = tqdm(total=source.expected_frames(), unit="frame", disable=not progress, leave=True)

    detector_skips: dict[str, int] = {}

    def selected() -> int:
        """Frames of the recording selected so far: read, or skipped by the source."""
        return source.counts.read + sum(source.counts.skipped.values())

    def wire_frames() -> Iterator[FrameIn]:
        for frame in source.frames(topics):
            try:
                detections = [] if detector is None else detector.detect(frame, source)
            except SkipFrame as skip:
                detector_skips[skip.reason] = detector_skips.get(skip.reason, 0) + 1
            else:
                summary.frames_sent += 1
                summary.detections_sent += len(detections)
                yield frame_in(frame, detections)
            bar.update(selected() - bar.n)

    try:
        # The first frame (and its detections) before the first request: a detector that cannot
        # run is reported before anything reaches the service (no empty scene is left behind).
        frames = wire_frames()
        first = next(frames, None)
        if first is not None:
            summary.sink = post_batches(
                url,
                scene,
                batches(
                    itertools.chain([first], frames),
                    prefix or batch_prefix(source.name),
                    frames_per_batch,
                ),
                token=token,
                wait=wait,
            )
    finally:
        bar.update(selected() - bar.n)
        bar.close()
        summary.frames_read = selected()
        summary.skipped = dict(source.counts.skipped)
        for reason, count in detector_skips.items():
            summary.skipped[reason] = summary.skipped.get(reason, 0) + count
    return summary
