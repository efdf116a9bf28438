"""Reading back what an ingest sent, through the service's HTTP API."""

from __future__ import annotations

from typing import Any

import httpx


def scene_id(url: str, name: str) -> str:
    """The id of the scene named `name` (exactly one)."""
    scenes = httpx.get(f"{url}/v1/scenes").json()["scenes"]
    (found,) = [scene["id"] for scene in scenes if scene["name"] == name]
    return str(found)


def events(url: str, scene: str) -> list[dict[str, Any]]:
    """Every event of the scene."""
    found: list[dict[str, Any]] = []
    after: int | None = -1
    while after is not None:
        page = httpx.get(
            f"{url}/v1/scenes/{scene}/events", params={"after": after, "limit": 1000}
        ).json()
        found += page["events"]
        after = page["next_after"]
    return found


def nodes(url: str, scene: str) -> dict[str, dict[str, Any]]:
    """The published graph's nodes by label."""
    graph = httpx.get(f"{url}/v1/scenes/{scene}/graph").json()
    return {node["label"]: node for node in graph["nodes"]}


def batch_status(url: str, scene: str, batch_id: str) -> dict[str, Any]:
    """One batch's status record."""
    response = httpx.get(f"{url}/v1/scenes/{scene}/batches/{batch_id}")
    assert response.status_code == 200, response.text
    record: dict[str, Any] = response.json()
    return record


def scene_names(url: str) -> set[str]:
    """The names of every scene of the service."""
    return {str(scene["name"]) for scene in httpx.get(f"{url}/v1/scenes").json()["scenes"]}


def batch_exists(url: str, scene: str, batch_id: str) -> bool:
    """Whether the scene holds a batch of this id."""
    response = httpx.get(f"{url}/v1/scenes/{scene}/batches/{batch_id}")
    assert response.status_code in (200, 404), response.text
    return response.status_code == 200
