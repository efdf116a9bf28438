"""The worker: claim a batch, decode it, decide, and append events + projections + done atomically."""

from __future__ import annotations

import logging
import os
import socket
import threading
import uuid
from collections import OrderedDict

from api_schema import BatchIn
from core.decide import decide
from core.state import SceneState
from service.bootstrap import Container
from service.codec import decode_batch
from service.store.errors import ConcurrencyConflict, LeaseLost
from service.store.queue import Claim

logger = logging.getLogger("pbdag.worker")


def worker_name() -> str:
    """host:pid:random, unique per worker instance."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


class Worker:
    """Processes queued batches, one scene's batches in arrival order."""

    def __init__(self, container: Container, name: str | None = None) -> None:
        self.container = container
        self.name = name or worker_name()
        self._states: OrderedDict[str, SceneState] = OrderedDict()

    def run_once(self) -> bool:
        """Requeue expired leases, then process one batch; False when none was waiting."""
        settings = self.container.settings
        self.container.queue.requeue_expired(settings.max_attempts)
        claim = self.container.queue.claim(self.name, settings.lease_seconds)
        if claim is None:
            return False
        self.process(claim)
        return True

    def run(self, stop: threading.Event) -> None:
        """Loop until `stop` is set, sleeping briefly when the queue is empty."""
        logger.info("worker %s started", self.name)
        while not stop.is_set():
            try:
                busy = self.run_once()
            except Exception:  # the database may be briefly unavailable; keep the worker alive
                logger.exception("worker %s: queue error", self.name)
                busy = False
            if not busy:
                stop.wait(self.container.settings.worker_poll_seconds)
        logger.info("worker %s stopped", self.name)

    def drain(self, max_batches: int = 1_000_000) -> int:
        """Process until the queue is empty; the number of batches processed."""
        processed = 0
        while processed < max_batches and self.run_once():
            processed += 1
        return processed

    def process(self, claim: Claim) -> None:
        """One batch end to end; failures are recorded on the batch, never raised."""
        container = self.container
        try:
            body = container.blobs.get(claim.blob_key)
            batch = decode_batch(BatchIn.model_validate_json(body))
            state = self._state(claim.scene_id)
            events = decide(state, batch)
            with container.uow.begin() as work:
                appended = work.append(claim.scene_id, state, events, batch_id=claim.batch_id)
                work.complete(claim, appended.seqs)
        except LeaseLost:
            self._states.pop(claim.scene_id, None)
            logger.warning("worker %s lost the lease of batch %s", self.name, claim.batch_id)
            return
        except ConcurrencyConflict as error:
            self._states.pop(claim.scene_id, None)
            self._fail(claim, f"concurrency conflict: {error}")
            return
        except Exception as error:
            self._states.pop(claim.scene_id, None)
            logger.exception("worker %s: batch %s failed", self.name, claim.batch_id)
            self._fail(claim, f"{type(error).__name__}: {error}")
            return
        self._remember(claim.scene_id, appended.state)

    def _fail(self, claim: Claim, error: str) -> None:
        try:
            status = self.container.queue.fail(claim, error, self.container.settings.max_attempts)
            logger.warning("batch %s %s: %s", claim.batch_id, status, error)
        except LeaseLost:
            logger.warning("batch %s: lease lost before recording %s", claim.batch_id, error)

    def _state(self, scene_id: str) -> SceneState:
        """The scene's state at its head: the cached one if nobody appended since, else loaded."""
        head = self.container.log.scene(scene_id).head_seq
        cached = self._states.get(scene_id)
        if cached is not None and cached.head_seq == head:
            self._states.move_to_end(scene_id)
            return cached
        return self.container.log.load_state(scene_id)

    def _remember(self, scene_id: str, state: SceneState) -> None:
        self._states[scene_id] = state
        self._states.move_to_end(scene_id)
        while len(self._states) > self.container.settings.state_cache_scenes:
            self._states.popitem(last=False)


class WorkerThread:
    """A worker in a background thread of the API process (`pbdag serve`)."""

    def __init__(self, container: Container) -> None:
        self.worker = Worker(container)
        self.stop = threading.Event()
        self.thread = threading.Thread(
            target=self.worker.run, args=(self.stop,), name="pbdag-worker", daemon=True
        )

    def start(self) -> None:
        """Start polling."""
        self.thread.start()

    def close(self) -> None:
        """Stop after the batch in hand."""
        self.stop.set()
        self.thread.join(timeout=30)
