"""Batches the API decoded, handed to the worker of the same process so it does not decode them
again (`pbdag serve` with its in-process worker).

The API decodes every posted batch to validate it (422 naming the field, nothing stored). The
worker would decode the same canonical body again from the stored blob: for a 640x480 png16
frame that is most of a batch's decoding. Decoding the stored canonical JSON gives the same
`Batch` as decoding the posted body, so the API's decode can stand for the worker's.

The hand-off is keyed by the queue row's id and its blob's key (content-addressed, naming the
scene: a row id a database reuses after a scene is deleted names another blob), and taken once. It is bounded in bytes (the
decoded depth images and the masks' runs); a batch that does not fit is not kept, and the
oldest ones go first. A batch that is not found (evicted, retried after a failure, posted to
another process, or after a restart) is decoded from its stored blob as before: the hand-off
only saves work, it never decides what the worker does.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from core.observation import Batch


def decoded_bytes(batch: Batch) -> int:
    """The memory a decoded batch holds: its depth images and its masks' run lengths."""
    return sum(
        frame.depth.nbytes + sum(detection.mask.runs.nbytes for detection in frame.detections)
        for frame in batch.frames
    )


Key = tuple[int, str]  # (queue row id, blob key)


class Handoff:
    """Decoded batches by (queue row id, blob key), at most `max_bytes` in all (0: nothing)."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._batches: OrderedDict[Key, tuple[Batch, int]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def put(self, key: Key, batch: Batch) -> None:
        """Keep `batch` for the worker, evicting the oldest to make room."""
        size = decoded_bytes(batch)
        if size > self.max_bytes:
            return
        with self._lock:
            previous = self._batches.pop(key, None)
            if previous is not None:
                self._bytes -= previous[1]
            while self._batches and self._bytes + size > self.max_bytes:
                _, (_, evicted) = self._batches.popitem(last=False)
                self._bytes -= evicted
            self._batches[key] = (batch, size)
            self._bytes += size

    def take(self, key: Key) -> Batch | None:
        """The batch kept for this row and blob, removed; None when none is."""
        with self._lock:
            kept = self._batches.pop(key, None)
            if kept is None:
                return None
            self._bytes -= kept[1]
            return kept[0]

    @property
    def held_bytes(self) -> int:
        """Bytes held now."""
        return self._bytes
