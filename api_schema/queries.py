"""Wire models of the questions asked in the robot's terms: objects by label, place, support
and change; objects that look like an appearance vector; one object's places over time."""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field, field_validator

from api_schema.requests import EmbeddingValue, NonEmptyLabel

# Values of one appearance vector: the batches' own limit (PBDAG_MAX_EMBEDDING_LENGTH's default).
MAX_EMBEDDING_LENGTH = 4096
MAX_SIMILAR = 100


class ObjectOut(BaseModel):
    """One object track as a question about it is answered: what, where, on what, since when."""

    track_id: str
    label: str = Field(description="The most likely class (ties by name).")
    class_probabilities: dict[str, float] = Field(description="p_cls, the class belief.")
    state: str = Field(description="Lifecycle state: tentative, confirmed, demoted, removed.")
    p_exist: float
    center: list[float] = Field(description="Metres, the latest accepted centre.")
    parent: str | None = Field(description="Track id of the fixture it rests on, or null.")
    parent_label: str | None = Field(description="That fixture's class, or null.")
    last_observed: float | None = Field(
        description="Time of its last sighting on the robot's clock (unix seconds)."
    )
    last_observed_frame: str | None = Field(description="Frame id of its last sighting.")
    changed_seq: int = Field(description="Seq of the track's last event at or before `seq`.")
    distance: float | None = Field(
        None, description="Metres from `near`, when the question gave a point."
    )


class ObjectPage(BaseModel):
    """`GET /v1/scenes/{scene_id}/objects`: one page of the answer, at `seq`."""

    scene_id: str
    seq: int = Field(description="The seq answered; pass it as `as_of` to page on it.")
    objects: list[ObjectOut]
    next_after: str | None = Field(
        description="Track id to pass as `after` for the next page (null at the end)."
    )


class SimilarIn(BaseModel):
    """Body of `POST /v1/scenes/{scene_id}/objects/similar`."""

    model_config = ConfigDict(extra="forbid")

    embedding: list[EmbeddingValue] = Field(
        min_length=1,
        max_length=MAX_EMBEDDING_LENGTH,
        description="An appearance vector of the scene's dimension (its tracks' appearance); "
        "not all zero.",
    )
    k: int = Field(5, ge=1, le=MAX_SIMILAR, description="How many objects to answer.")
    label: NonEmptyLabel | None = Field(None, description="Only objects of this class.")

    @field_validator("embedding")
    @classmethod
    def _not_zero(cls, embedding: list[float]) -> list[float]:
        if math.hypot(*embedding) == 0.0:
            raise ValueError("a zero vector has no direction to compare")
        return embedding


class SimilarMatch(ObjectOut):
    """An object and how much it looks like the vector asked about."""

    score: float = Field(description="Cosine of the vector and the track's appearance.")


class SimilarOut(BaseModel):
    """The `k` objects whose appearance is closest to the vector, best first."""

    scene_id: str
    seq: int
    matches: list[SimilarMatch]


class HistorySpan(BaseModel):
    """A stretch of a track's events with one place, one parent and one lifecycle state."""

    from_seq: int = Field(description="Seq of the span's first event.")
    to_seq: int = Field(description="Seq of its last event (the next span starts after it).")
    from_time: float | None = Field(
        description="Robot clock of the batch of its first event (null: a command, or a row "
        "stored before the log kept the batch's time)."
    )
    to_time: float | None = Field(description="Robot clock of the batch of its last event.")
    parent: str | None = Field(description="The fixture it rested on.")
    center: list[float] = Field(description="Its centre at the end of the span, metres.")
    state: str = Field(description="Its lifecycle state in the span.")
    last_observed: float | None = Field(description="Its last sighting in the span (robot clock).")
    events: int = Field(description="How many of its events the span holds.")


class TrackHistory(BaseModel):
    """`GET /v1/scenes/{scene_id}/tracks/{track_id}/history`: its spans in seq order."""

    scene_id: str
    track_id: str
    seq: int = Field(description="The seq answered (the head, or `as_of`).")
    spans: list[HistorySpan]
    next_after: int | None = Field(
        description="Seq to pass as `after` for the next page of spans (null at the end)."
    )
