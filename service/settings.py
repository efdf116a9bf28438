"""All configuration, from PBDAG_* environment variables; nothing else reads the environment."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator
from pydantic_settings import SettingsConfigDict

from codec.observations import InputLimits
from pbdag_errors import Refused
from service.security_settings import SecuritySettings, with_database_password

POSTGRES_SCHEMES = ("postgres://", "postgresql://")  # normalised to postgresql+psycopg://
DURATION_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def parse_duration(text: str) -> float | None:
    """Seconds of `7d`, `12h`, `90m`, `30s` or `3600`; None for empty or `none`."""
    value = text.strip().lower()
    if value in ("", "none"):
        return None
    unit = DURATION_UNITS.get(value[-1])
    number = value[:-1] if unit is not None else value
    try:
        seconds = float(number) * (unit or 1.0)
    except ValueError:
        raise ValueError(
            f"{text!r} is not a duration (seconds, or a number with s, m, h or d)"
        ) from None
    if not seconds >= 0 or seconds == float("inf"):
        raise ValueError(f"{text!r}: a duration is a finite number of seconds >= 0")
    return seconds


class SettingsError(Refused, ValueError):
    """Settings that cannot work together; the command stops at start, naming the variables."""


class Settings(SecuritySettings):
    """Service settings (environment prefix PBDAG_; security ones in service/security_settings.py)."""

    model_config = SettingsConfigDict(env_prefix="PBDAG_", extra="ignore")

    # `pbdag serve` and `pbdag worker` (their options override these).
    host: str = Field(
        "127.0.0.1",
        description="Address `pbdag serve` listens on; a non-loopback one needs an active token.",
    )
    port: int = Field(8000, ge=1, le=65535, description="Port `pbdag serve` listens on.")
    run_worker: bool = Field(
        True, description="`pbdag serve` runs a worker in its process (false: API only)."
    )
    log_format: Literal["text", "json"] = Field(
        "text",
        description="Log lines as text, or one JSON object per line (with scene and batch ids).",
    )
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = Field(
        "INFO", description="Least severe log level written."
    )
    metrics_port: int = Field(
        0,
        ge=0,
        le=65535,
        description="`pbdag worker` serves its Prometheus metrics on this loopback port (0: none).",
    )
    data_dir: Path = Field(
        Path("./data"), description="Blobs and the default SQLite database live here."
    )
    database_url: str | None = Field(
        None,
        description="SQLAlchemy URL; default sqlite:///<data_dir>/pbdag.db. PostgreSQL: "
        "postgresql+psycopg://... (postgres:// and postgresql:// mean the same: psycopg 3).",
    )
    blob_backend: Literal["auto", "postgres", "folder"] = Field(
        "auto",
        description="Where raw batches are kept: `postgres` (a table, written in the transaction "
        "that queues the batch; processes share only the database), `folder` (files under "
        "<data_dir>/blobs, shared by every process), `auto` (postgres on PostgreSQL, folder on "
        "SQLite).",
    )
    max_body_bytes: int = Field(
        32 * 1024 * 1024, ge=1024, description="Largest accepted request body (413 beyond)."
    )
    # What one request may ask the service to decode (422 naming the field and the limit).
    max_frames_per_batch: int = Field(16, ge=1, le=1024, description="Frames per batch.")
    max_detections_per_frame: int = Field(
        256, ge=1, le=100_000, description="Detections per frame."
    )
    max_image_pixels: int = Field(
        2_400_000, ge=1, le=8192 * 8192, description="Width x height of a frame (1920 x 1200 fits)."
    )
    max_embedding_length: int = Field(4096, ge=1, description="Values of one appearance embedding.")
    max_class_scores: int = Field(64, ge=1, description="Entries of one detection's class_scores.")
    max_label_length: int = Field(100, ge=1, le=200, description="Characters of a label.")
    max_mask_pixels_per_batch: int = Field(
        40_000_000, ge=1, description="Pixels all masks of a batch cover together."
    )
    # Backpressure and quotas.
    max_queued_batches_per_scene: int = Field(
        256,
        ge=1,
        description="Unfinished batches a scene may hold; more are a 429 with Retry-After.",
    )
    queue_full_retry_after_seconds: int = Field(
        2, ge=1, description="Retry-After of a 429 for a full scene queue."
    )
    max_scene_blob_bytes: int = Field(
        20 * 1024**3, ge=1, description="Raw batch bytes a scene may store; more are a 507."
    )
    raw_retention: float | None = Field(
        None,
        ge=0,
        description="How long `pbdag gc` keeps a done or dead batch's raw body after it finished: "
        "seconds, or a number with s, m, h or d (e.g. 7d); unset keeps every raw batch. "
        "Events are kept forever; a batch still queued or running, and one holding the frame "
        "of a pending verification or of an unresolved inspection, is kept.",
    )
    lease_seconds: float = Field(
        60.0,
        gt=0,
        description="A claimed batch's lease; the worker renews it every third of this while it "
        "works, and a batch whose worker stopped renewing returns to the queue.",
    )
    max_attempts: int = Field(
        8,
        ge=1,
        description="A batch failing this often for a passing reason (database unavailable...) is "
        "parked as dead; a batch that can never succeed is dead at once.",
    )
    retry_base_seconds: float = Field(
        0.5, gt=0, description="First retry delay; doubles per attempt, with jitter."
    )
    retry_max_seconds: float = Field(60.0, gt=0, description="Longest retry delay.")
    snapshot_interval: int = Field(
        500,
        description="Store a state snapshot every this many events (as_of decodes the newest "
        "one at or before its seq and folds the events after it).",
    )
    worker_poll_seconds: float = Field(0.05, description="Idle worker polling period.")
    state_cache_scenes: int = Field(
        64, description="Scene states a worker keeps in memory between batches."
    )
    handoff_max_bytes: int = Field(
        64 * 1024 * 1024,
        ge=0,
        description="`pbdag serve` with its worker hands the batches its API decoded to the "
        "worker, up to this many bytes in all, so they are not decoded twice (0: off).",
    )
    # The live change feed (`GET /v1/scenes/{id}/events/stream`).
    max_streams: int = Field(
        64,
        ge=1,
        le=10_000,
        description="Event streams one API process keeps open; more are a 503 with Retry-After.",
    )
    stream_poll_seconds: float = Field(
        0.25,
        ge=0.01,
        le=60,
        description="How often an idle event stream reads the scene's head from the log (new "
        "events may come from a worker in any process).",
    )
    stream_listen: bool = Field(
        True,
        description="On PostgreSQL, wake the event streams by LISTEN/NOTIFY as soon as events are "
        "committed (one connection per API process); they poll the log all the same.",
    )
    stream_heartbeat_seconds: float = Field(
        10.0,
        ge=0.05,
        le=300,
        description="An event stream with nothing to send writes a comment line this often, so "
        "proxies and clients see the connection alive.",
    )
    stream_write_timeout_seconds: float = Field(
        10.0,
        ge=0.05,
        le=300,
        description="A consumer that has not taken a write within this many seconds is dropped "
        "(a last `dropped` message, then the stream closes).",
    )
    stream_max_unsent_bytes: int = Field(
        1024 * 1024,
        ge=4096,
        le=64 * 1024 * 1024,
        description="Bytes of events an event stream holds for its consumer: the log is read "
        "only as fast as the consumer takes them, at most this much at a time.",
    )

    @field_validator("database_url")
    @classmethod
    def _psycopg(cls, value: str | None) -> str | None:
        """`postgres://` (Heroku, libpq) and `postgresql://` use psycopg 3, the driver installed
        (SQLAlchemy would look for psycopg2, or not know `postgres` at all)."""
        if value is None:
            return None
        for scheme in POSTGRES_SCHEMES:
            if value.startswith(scheme):
                return "postgresql+psycopg://" + value[len(scheme) :]
        return value

    @field_validator("raw_retention", mode="before")
    @classmethod
    def _duration(cls, value: object) -> object:
        """`7d`, `12h`, `90m`, `30s` or plain seconds; empty or `none` for unset."""
        if isinstance(value, str):
            return parse_duration(value)
        return value

    def input_limits(self) -> InputLimits:
        """The decoding limits of one request."""
        return InputLimits(
            max_frames_per_batch=self.max_frames_per_batch,
            max_detections_per_frame=self.max_detections_per_frame,
            max_image_pixels=self.max_image_pixels,
            max_embedding_length=self.max_embedding_length,
            max_class_scores=self.max_class_scores,
            max_label_length=self.max_label_length,
            max_mask_pixels_per_batch=self.max_mask_pixels_per_batch,
        )

    def resolved_database_url(self) -> str:
        """The database URL, defaulting to the SQLite file under the data directory."""
        if self.database_url:
            return with_database_password(self.database_url, self.database_password)
        return f"sqlite:///{(self.data_dir / 'pbdag.db').resolve()}"
