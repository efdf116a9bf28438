"""Wire models of a scene's lifecycle after its creation: rename and delete."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from api_schema.requests import NonEmptyLabel


class SceneRename(BaseModel):
    """Body of `PATCH /v1/scenes/{scene_id}`."""

    model_config = ConfigDict(extra="forbid")

    name: NonEmptyLabel = Field(
        description="The scene's new name (the same rule as a new scene's name); recorded in "
        "the scene's log as a `scene_renamed` event."
    )


class SceneDeleted(BaseModel):
    """What `DELETE /v1/scenes/{scene_id}` removed, in one transaction."""

    scene_id: str = Field(description="The deleted scene's id.")
    events: int = Field(description="Event rows deleted: the scene's whole log.")
    tracks: int = Field(description="Rows of the track table deleted.")
    snapshots: int = Field(description="State snapshots deleted.")
    baselines: int = Field(
        description="Frozen baseline packages deleted (scenes created from one keep their copy)."
    )
    batches: int = Field(description="Queue rows deleted, whatever their status.")
    blobs: int = Field(
        description="Raw batch blobs deleted: those no other scene's batch names. A folder blob "
        "the store could not delete is left to `pbdag gc`'s sweep and not counted."
    )
    bytes: int = Field(description="Bytes of the blobs counted in `blobs`.")
