"""The worker: claim a batch, decode it, decide, and append events + projections + done atomically.

Failures are of two kinds. A passing one (the store's `StoreUnavailable`: the database or the
blob store could not answer; or `ConcurrencyConflict`: another writer first) is retried with
exponential backoff and jitter, up to `max_attempts`. A batch that can never succeed (it does not
decode, or deciding it fails or yields a non-finite number) is parked as dead at once, and the
scene moves on: the log records the gap (`batch_skipped`), so a bad batch never stalls a robot's
memory and never hides. Errors stored on a batch are short; the details go to the server log.
The store translates driver and file-system errors at its adapter: the worker knows only the
project's own exceptions. A batch whose scene an administrator deleted while it was worked on
(its queue row went with the scene) is dropped with one line: nothing is recorded, nothing of
the scene is written again.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import random
import socket
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Iterator
from contextlib import contextmanager

import orjson
import pydantic

from api_schema import BatchIn
from codec.observations import decode_batch
from core.decide import decide
from core.observation import Batch
from core.state import SceneState
from pbdag_errors import PbdagError
from service.bootstrap import Container
from service.handoff import Handoff
from service.logs import log_context
from service.store.blobs import BlobNotFound, RawBatchMissing
from service.store.errors import (
    ConcurrencyConflict,
    LeaseLost,
    SceneNotFound,
    StoreUnavailable,
)
from service.store.queue_records import Claim, RawBatchCollected
from service.store.raw_batches import raw_batch_parts

logger = logging.getLogger("pbdag.worker")

# Failures that may pass: the same batch can succeed on a later attempt.
TRANSIENT = (StoreUnavailable, ConcurrencyConflict)
MAX_ERROR_CHARS = 300


def worker_name() -> str:
    """host:pid:random, unique per worker instance."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def operator_cause(error: BaseException) -> str:
    """What failed, for the operator (the store's own words, never a batch's content)."""
    text = error.detail if isinstance(error, PbdagError) else f"{type(error).__name__}: {error}"
    return text[:MAX_ERROR_CHARS]


def short_error(error: BaseException) -> tuple[str, bool]:
    """(the message a client may read, whether a retry may succeed)."""
    if isinstance(error, TRANSIENT):
        cause = error.cause_name if isinstance(error, StoreUnavailable) else type(error).__name__
        return f"{cause}: the database or the blob store failed; will retry", True
    if isinstance(error, pydantic.ValidationError):
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        message = f"invalid batch: {where}: {first['msg']}"
    elif isinstance(error, PbdagError):
        message = f"rejected: {error.detail}"
    else:
        message = f"internal error ({type(error).__name__}) while deciding; see the server log"
    return message[:MAX_ERROR_CHARS], False


def expected_rejection(error: BaseException) -> bool:
    """Whether a failure is the batch's own (invalid, or refused by the memory), not a bug."""
    return isinstance(error, pydantic.ValidationError | PbdagError)


@dataclasses.dataclass(frozen=True)
class WorkerHealth:
    """Whether the worker can record what it does; when not, why and since when."""

    healthy: bool = True
    problem: str | None = None
    since: float | None = None


class Worker:
    """Processes queued batches, one scene's batches in arrival order.

    A worker that cannot write (a full disk, a read-only or lost database) keeps each failure
    it could not record and records it before it claims anything else, once writing works
    again; meanwhile it claims nothing and `health` says why."""

    def __init__(
        self,
        container: Container,
        name: str | None = None,
        seed: int | None = None,
        handoff: Handoff | None = None,
    ) -> None:
        self.container = container
        self.handoff = handoff  # batches the API of this process decoded
        self.name = name or worker_name()
        self._states: OrderedDict[str, SceneState] = OrderedDict()
        self._random = random.Random(seed)
        self._unrecorded: dict[int, tuple[Claim, str, bool]] = {}  # by batch row id
        self._settled_at: float | None = None  # the queue's clock when leases were last settled
        self.health = WorkerHealth()

    def _healthy(self) -> None:
        if not self.health.healthy:
            logger.info("worker %s can record again (was: %s)", self.name, self.health.problem)
        self.health = WorkerHealth()
        self.container.metrics.worker_healthy.set(1)

    def _unhealthy(self, problem: str) -> None:
        if self.health.healthy or self.health.problem != problem:
            self.health = WorkerHealth(False, problem, self.health.since or time.time())
            self.container.metrics.worker_healthy.set(0)

    def run_once(self) -> bool:
        """Record the failures not yet recorded, settle expired leases, then process one batch;
        False when none was due (or the worker cannot write)."""
        settings = self.container.settings
        if not self._record_unrecorded():
            return False
        if self._settle_due():
            self.settle_expired()
        claim = self.container.queue.claim(self.name, settings.lease_seconds)
        self._recovered("cannot reach")
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
            except Exception as error:  # the database may be unavailable; keep the worker alive
                self._unhealthy(f"cannot reach the queue: {operator_cause(error)}")
                logger.error("worker %s: queue error: %s", self.name, operator_cause(error))
                busy = False
            if not busy:
                stop.wait(self.container.settings.worker_poll_seconds)
        logger.info("worker %s stopped", self.name)

    def drain(self, max_batches: int = 1_000_000) -> int:
        """Process until no batch is due; the number of batches processed."""
        processed = 0
        while processed < max_batches and self.run_once():
            processed += 1
        return processed

    def process(self, claim: Claim) -> None:
        """One batch end to end; failures are recorded on the batch, never raised."""
        with log_context(scene_id=claim.scene_id, batch_id=claim.batch_id):
            self._process(claim)

    def _process(self, claim: Claim) -> None:
        container = self.container
        metrics = container.metrics
        try:
            with self._renewing(claim):
                with metrics.timed(metrics.decide_seconds):
                    batch = self._batch(claim)
                    state = self._state(claim.scene_id, claim.head_seq)
                    events = decide(state, batch)
                with metrics.timed(metrics.append_seconds), container.uow.begin() as work:
                    appended = work.append(
                        claim.scene_id,
                        state,
                        events,
                        batch_id=claim.batch_id,
                        batch_time=max(frame.timestamp for frame in batch.frames),
                    )
                    work.complete(claim, appended.seqs)
        except LeaseLost:
            self._states.pop(claim.scene_id, None)
            if self._dropped(claim):
                return
            metrics.batches_processed.labels("lease_lost").inc()
            logger.warning("worker %s lost the lease of batch %s", self.name, claim.batch_id)
            return
        except Exception as error:
            self._states.pop(claim.scene_id, None)
            if not self._dropped(claim):
                self._failed(claim, error)
            return
        metrics.batches_processed.labels("done").inc()
        self._healthy()
        logger.info(
            "batch %s of scene %s done: %d events%s",
            claim.batch_id,
            claim.scene_id,
            len(events),
            "" if appended.seqs is None else f", seq {appended.seqs[0]}..{appended.seqs[1]}",
        )
        self._remember(claim.scene_id, appended.state)

    def _dropped(self, claim: Claim) -> bool:
        """Whether the claim's scene was deleted (its batch went with it): then one line says
        the batch is dropped, and there is nothing to record. False when the scene exists or
        cannot be read now (the failure is then recorded as any other)."""
        try:
            self.container.log.scene(claim.scene_id)
        except SceneNotFound:
            self._states.pop(claim.scene_id, None)
            self.container.metrics.batches_processed.labels("dropped").inc()
            logger.info(
                "batch %s dropped: its scene %s was deleted", claim.batch_id, claim.scene_id
            )
            return True
        except Exception:
            return False
        return False

    def _batch(self, claim: Claim) -> Batch:
        """The claimed batch decoded: as this process's API decoded it when handed over, else
        from its stored blob."""
        handed = None if self.handoff is None else self.handoff.take((claim.id, claim.blob_key))
        if handed is not None:
            self.container.metrics.batches_handed_off.inc()
            return handed
        # The body without its depth, validated as the API validated it (JSON), and the depth
        # decoded from its stored bytes: not base64-encoded into the body to be decoded again.
        body, depths = raw_batch_parts(self._raw_body(claim))
        wire = BatchIn.model_validate_json(orjson.dumps(body))
        return decode_batch(wire, self.container.settings.input_limits(), depths)

    def _raw_body(self, claim: Claim) -> bytes:
        """The stored batch; RawBatchCollected when `pbdag gc` deleted it (a copy made by
        `pbdag repair` of a collected batch), RawBatchMissing when it is gone otherwise."""
        if claim.blob_collected_at is not None:
            raise RawBatchCollected(claim.batch_id, claim.blob_collected_at)
        try:
            return self.container.blobs.get(claim.blob_key)
        except BlobNotFound:
            raise RawBatchMissing(claim.batch_id, claim.blob_key) from None

    def _failed(self, claim: Claim, error: BaseException) -> None:
        message, transient = short_error(error)
        logger.error(
            "batch %s of scene %s failed (attempt %d): %s",
            claim.batch_id,
            claim.scene_id,
            claim.attempts,
            message,
            # A rejection (invalid input, a refused command) is the batch's, not a bug: its one
            # line says it all. The traceback is for the unexpected, or when debugging.
            exc_info=not (transient or expected_rejection(error))
            or logger.isEnabledFor(logging.DEBUG),
        )
        try:
            self._record(claim, message, transient)
        except LeaseLost:
            logger.warning("batch %s: lease lost before recording %s", claim.batch_id, message)
        except Exception as error:
            self._unrecorded[claim.id] = (claim, message, transient)
            cause = operator_cause(error)
            self._unhealthy(f"cannot record the failure of batch {claim.batch_id}: {cause}")
            logger.error(
                "batch %s: could not record its failure (%s); recorded once writing works again",
                claim.batch_id,
                cause,
            )

    def _record(self, claim: Claim, message: str, transient: bool) -> None:
        if transient and claim.attempts < self.container.settings.max_attempts:
            self.container.queue.retry_later(claim, message, self.retry_delay(claim.attempts))
            self.container.metrics.batches_processed.labels("retry").inc()
        else:
            self.skip(claim, message)

    def _record_unrecorded(self) -> bool:
        """Record the failures kept while writing failed; False while that still fails."""
        for key, (claim, message, transient) in list(self._unrecorded.items()):
            try:
                self._record(claim, message, transient)
            except LeaseLost:
                pass  # another worker settled it when the lease expired
            except Exception as error:
                if self._dropped(claim):  # its scene was deleted meanwhile
                    del self._unrecorded[key]
                    continue
                cause = operator_cause(error)
                self._unhealthy(f"cannot record the failure of batch {claim.batch_id}: {cause}")
                return False
            del self._unrecorded[key]
            logger.info("batch %s: its failure is recorded now: %s", claim.batch_id, message)
        self._recovered("cannot record")
        return True

    def _recovered(self, problem: str) -> None:
        if (self.health.problem or "").startswith(problem):
            self._healthy()

    @property
    def unrecorded(self) -> int:
        """Failures the worker holds because it could not record them yet."""
        return len(self._unrecorded)

    def retry_delay(self, attempts: int) -> float:
        """Exponential backoff with jitter: base * 2^(attempts - 1), capped, times 0.5-1.5."""
        settings = self.container.settings
        delay = min(settings.retry_max_seconds, settings.retry_base_seconds * 2 ** (attempts - 1))
        return float(delay * self._random.uniform(0.5, 1.5))

    def skip(self, claim: Claim, reason: str) -> None:
        """Dead, and the gap recorded in the scene's log, in one transaction (on the new head
        when a command appended meanwhile)."""
        self.container.uow.on_the_head(
            claim.scene_id,
            lambda _state: None,  # nothing to decide: the gap is recorded on whatever head
            lambda work, state, _nothing: work.skip(claim, state, reason),
        )
        self.container.metrics.batches_processed.labels("dead").inc()
        self.container.metrics.dead_letters.inc()
        logger.warning("batch %s of scene %s is dead: %s", claim.batch_id, claim.scene_id, reason)

    def _settle_due(self) -> bool:
        """Whether to look for expired leases now: at the first call, then once every third of
        a lease (the heartbeat's beat), not before every batch. A lease lapses a whole lease
        after its last renewal, so a crashed worker's batch returns to the queue at most a
        third of a lease later than it could; a busy worker saves a query per batch."""
        now = self.container.queue.clock()
        if self._settled_at is not None and now - self._settled_at < (
            self.container.settings.lease_seconds / 3
        ):
            return False
        self._settled_at = now
        return True

    def settle_expired(self) -> None:
        """Leases nobody renewed: back to the queue with backoff, or dead when out of attempts."""
        settings = self.container.settings
        for claim in self.container.queue.expired():
            reason = f"lease expired on attempt {claim.attempts} (the worker stopped)"
            try:
                with log_context(scene_id=claim.scene_id, batch_id=claim.batch_id):
                    if claim.attempts < settings.max_attempts:
                        self.container.queue.retry_later(
                            claim, reason, self.retry_delay(claim.attempts)
                        )
                    else:
                        self.skip(claim, reason)
            except (LeaseLost, SceneNotFound):
                continue  # another worker settled it first, or the scene was deleted

    @contextmanager
    def _renewing(self, claim: Claim) -> Iterator[None]:
        """Renew the lease every third of its length while the batch is worked on."""
        lease = self.container.settings.lease_seconds
        stop = threading.Event()

        def heartbeat() -> None:
            while not stop.wait(lease / 3):
                try:
                    if not self.container.queue.renew(claim, lease):
                        logger.warning("batch %s: lease lost while working", claim.batch_id)
                        return
                except Exception:
                    logger.exception("batch %s: lease renewal failed", claim.batch_id)

        beat = threading.Thread(target=heartbeat, name="pbdag-lease", daemon=True)
        beat.start()
        try:
            yield
        finally:
            stop.set()
            beat.join()

    def _state(self, scene_id: str, head: int | None = None) -> SceneState:
        """The scene's state at its head (`head` when the claim read it, else read here): the
        cached one if nobody appended since, else loaded. A command appended after the claim
        makes the append's head check fail, as one appended after a read here would."""
        if head is None:
            head = self.container.log.scene(scene_id).head_seq
        cached = self._states.get(scene_id)
        if cached is not None and cached.head_seq == head:
            self._states.move_to_end(scene_id)
            return cached
        loaded = self.container.log.load_state(scene_id)
        if cached is not None and loaded.voxels == cached.voxels:
            # A command appended meanwhile (a verdict, a plan) and left the fixture voxel map
            # as it was: keep the cached map, whose clusters need not be built anew.
            loaded = dataclasses.replace(loaded, voxels=cached.voxels)
        return loaded

    def _remember(self, scene_id: str, state: SceneState) -> None:
        self._states[scene_id] = state
        self._states.move_to_end(scene_id)
        while len(self._states) > self.container.settings.state_cache_scenes:
            self._states.popitem(last=False)


class WorkerThread:
    """A worker in a background thread of the API process (`pbdag serve`)."""

    def __init__(self, container: Container, handoff: Handoff | None = None) -> None:
        self.worker = Worker(container, handoff=handoff)
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
