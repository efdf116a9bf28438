"""The text rule (api_schema.text) over HTTP: non-characters, lone surrogates, controls and DEL
are a 422 problem naming the field, wherever a name or label goes, and nothing is stored."""

from __future__ import annotations

import json
import re

import httpx2
import pytest
from fastapi.testclient import TestClient

from api_schema.text import PRINTABLE, first_refused, kind_of, replace_refused
from tests.wire_bodies import batch_body, frame_body

# What XML 1.0 forbids (U+FFFE, U+FFFF), the other non-characters (the first and last of the
# U+FDD0 block, a supplementary plane's and the last plane's), DEL and a C0 control.
REFUSED = ["\ufffe", "\uffff", "\ufdd0", "\ufdef", "\U0001fffe", "\U0010ffff", "\x7f", "\x1f"]
# Text that must still pass: accents, CJK, an emoji, the replacement character, private use,
# and a C1 control (XML 1.0 and JSON allow it; the rule does not refuse it).
ACCEPTED = ["tasse à café", "马克杯", "mug 🍵", "\ufffd", "\ue000", "a\x85b"]


def refused(response: httpx2.Response, field: str, character: str) -> None:
    """A 422 problem naming `field` and the character (as U+XXXX, never the text itself)."""
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == "application/problem+json"
    problem = response.json()
    assert problem["field"] == field, problem
    assert f"U+{ord(character):04X}" in problem["detail"], problem["detail"]
    assert problem["errors"][0]["field"] == field


def stored(client: TestClient, scene_id: str) -> tuple[int, int]:
    """(the scene's head seq, batches queued or done): what a refused post must not change."""
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    return head, sum(client.get("/healthz").json()["batches"].values())


@pytest.mark.parametrize("character", REFUSED, ids=lambda c: f"U+{ord(c):04X}")
def test_a_refused_character_in_a_scene_name_or_a_label_is_a_422_naming_the_field(
    client: TestClient, scene_id: str, character: str
) -> None:
    scenes = len(client.get("/v1/scenes").json()["scenes"])
    refused(client.post("/v1/scenes", json={"name": f"hall{character}"}), "name", character)
    assert len(client.get("/v1/scenes").json()["scenes"]) == scenes

    before = stored(client, scene_id)
    frame = frame_body()
    frame["detections"][0]["label"] = f"mu{character}g"
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch_body(frame))
    refused(response, "frames[0].detections[0].label", character)
    frame = frame_body(f"f{character}")
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch_body(frame))
    refused(response, "frames[0].frame_id", character)
    assert stored(client, scene_id) == before


def test_a_lone_surrogate_is_a_422_naming_the_field(client: TestClient, scene_id: str) -> None:
    # JSON can spell half of a UTF-16 pair ("\ud800"); Python's parser lets it through.
    body = json.dumps({"name": "hall"}).replace("hall", "ha\\ud800ll")
    response = client.post(
        "/v1/scenes", content=body.encode(), headers={"content-type": "application/json"}
    )
    refused(response, "name", "\ud800")
    verdict = '{"verdict": "confirm", "source": "op\\udfffx"}'
    response = client.post(
        f"/v1/scenes/{scene_id}/tracks/trk-000001/verification",
        content=verdict.encode(),
        headers={"content-type": "application/json"},
    )
    refused(response, "source", "\udfff")


def test_class_score_labels_and_verdict_sources_follow_the_rule(
    client: TestClient, scene_id: str
) -> None:
    before = stored(client, scene_id)
    frame = frame_body()
    frame["detections"][0]["class_scores"] = {"mug": 0.9, "cu\ufffep": 0.1}
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch_body(frame))
    assert response.status_code == 422, response.text
    field = response.json()["field"]
    assert field.startswith("frames[0].detections[0].class_scores"), field
    assert "U+FFFE" in response.json()["detail"]
    assert stored(client, scene_id) == before
    verdict = {"verdict": "reject", "source": "model\uffff"}
    response = client.post(f"/v1/scenes/{scene_id}/tracks/trk-000001/verification", json=verdict)
    refused(response, "source", "\uffff")


def test_a_text_query_with_a_non_character_is_a_422(client: TestClient, scene_id: str) -> None:
    for name in ("label", "parent"):
        response = client.get(f"/v1/scenes/{scene_id}/graph", params={name: "mu\uffffg"})
        assert response.status_code == 422, response.text
        assert response.json()["field"] == name


@pytest.mark.parametrize("name", ACCEPTED)
def test_other_text_is_stored_as_sent(client: TestClient, name: str) -> None:
    created = client.post("/v1/scenes", json={"name": name})
    assert created.status_code == 201, created.text
    assert client.get(f"/v1/scenes/{created.json()['id']}").json()["name"] == name


def test_the_rule_refuses_exactly_controls_del_surrogates_and_the_66_non_characters() -> None:
    refused_codes = [code for code in range(0x110000) if first_refused(chr(code)) is not None]
    refused_set = set(refused_codes)
    non_characters = [
        code
        for code in refused_codes
        if 0xFDD0 <= code <= 0xFDEF or (code & 0xFFFF) in (0xFFFE, 0xFFFF)
    ]
    assert len(non_characters) == 66
    assert refused_codes == sorted([*range(0x20), 0x7F, *range(0xD800, 0xE000), *non_characters])
    assert {kind_of(chr(code)) for code in (0x00, 0x7F, 0xD800, 0xFFFF)} == {
        "a control character",
        "DEL",
        "a lone surrogate",
        "a non-character",
    }
    # The schema's pattern states the same rule for every BMP character but the surrogates.
    pattern = re.compile(PRINTABLE)
    for code in [*range(0xD800), *range(0xE000, 0x10000)]:
        assert (pattern.fullmatch(chr(code)) is None) == (code in refused_set), hex(code)
    assert replace_refused("a\uffffb\x00c\U0001fffe") == "a\ufffdb\ufffdc\ufffd"
