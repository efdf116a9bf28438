"""Batches: accept observations durably, report their processing."""

from __future__ import annotations

import hashlib
import logging
from typing import Annotated

from fastapi import APIRouter, Path, Response

from api_schema import BatchIn, BatchStatus
from codec.canonical import canonical_json
from codec.observations import decode_batch
from core.errors import NotFound
from service.auth import RequireAdmin
from service.deps import ContainerDep, HandoffDep, SceneDep, admission
from service.store.raw_batches import encode_raw_batch
from service.wire import batch_out

router = APIRouter(prefix="/v1/scenes/{scene_id}/batches", tags=["batches"])
logger = logging.getLogger("pbdag.api")
BatchId = Annotated[str, Path(min_length=1, max_length=200, pattern=r"^[A-Za-z0-9._:-]+$")]


@router.post(
    "",
    status_code=202,
    response_model=BatchStatus,
    responses={200: {"model": BatchStatus, "description": "The same batch was already accepted."}},
)
def post_batch(
    scene: SceneDep,
    batch: BatchIn,
    response: Response,
    container: ContainerDep,
    handoff: HandoffDep,
) -> BatchStatus:
    """Validate and durably queue a batch (202); the same batch_id and content again returns the original (200)."""
    settings = container.settings
    decoded = decode_batch(batch, settings.input_limits())  # 422 naming the field; nothing stored
    # Idempotency is over the canonical JSON; the blob keeps it compactly (binary depth, zstd).
    body = batch.model_dump(mode="json")
    content_sha256 = hashlib.sha256(canonical_json(body)).hexdigest()
    # A re-post writes no blob (its raw body may have been collected by `pbdag gc`): submit
    # answers with the original, or 409 for different content.
    known = container.queue.get(scene.id, batch.batch_id) is not None
    stored = None if known else encode_raw_batch(body, scene.id)
    # Admission (429 / 507 before any write), the blob and the queue row (BatchQueue.submit).
    record, created = container.queue.submit(
        scene.id, batch.batch_id, content_sha256, stored, len(batch.frames), admission(settings)
    )
    if not created:
        response.status_code = 200
    elif handoff is not None:
        handoff.put(
            (record.id, record.blob_key), decoded
        )  # this process's worker takes it instead of decoding
    logger.info(
        "batch %s %s (%d frames)",
        batch.batch_id,
        "queued" if created else "already accepted",
        len(batch.frames),
        extra={"batch_id": batch.batch_id},
    )
    return batch_out(record)


@router.post("/{batch_id}/requeue", response_model=BatchStatus)
def requeue_batch(
    scene: SceneDep, batch_id: BatchId, container: ContainerDep, _admin: RequireAdmin
) -> BatchStatus:
    """Put a dead batch back in the queue (admin scope); it applies at its turn."""
    if container.queue.get(scene.id, batch_id) is None:
        raise NotFound("batch", batch_id, "batch_id")
    return batch_out(container.queue.requeue(scene.id, batch_id))


@router.get("/{batch_id}", response_model=BatchStatus)
def get_batch(scene: SceneDep, batch_id: BatchId, container: ContainerDep) -> BatchStatus:
    """Status of one batch and the seq range it appended."""
    record = container.queue.get(scene.id, batch_id)
    if record is None:
        raise NotFound("batch", batch_id, "batch_id")
    return batch_out(record)
