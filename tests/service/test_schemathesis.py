"""Schemathesis against the app in process: no server error, every answer as documented, and
what the schema calls valid accepted.

Bounded: a few examples per operation, so that the suite stays fast; `make fuzz` runs more.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)
from schemathesis.specs.openapi.checks import positive_data_acceptance

from core.params import Params
from service.app import create_app
from service.auth import create_token
from service.bootstrap import build_container
from service.commands import create_scene
from service.settings import Settings
from service.store.engine import make_engine

if TYPE_CHECKING:
    from schemathesis.specs.openapi.schemas import OpenApiCase

EXAMPLES = int(os.environ.get("PBDAG_FUZZ_EXAMPLES", "15"))
DATA = Path(os.environ.get("PBDAG_FUZZ_DIR", "/tmp")) / f"pbdag-schemathesis-{os.getpid()}"
DATA.mkdir(parents=True, exist_ok=True)
CONTAINER = build_container(
    Settings(data_dir=DATA, allowed_hosts=["*"], rate_limit_per_minute=0),
    engine=make_engine(f"sqlite:///{DATA / 'pbdag.db'}"),
)
TOKEN = create_token(CONTAINER.engine, "schemathesis", ["admin"]).token
# One scene exists, so that generated requests also reach past the 404 of an unknown scene.
SCENE = create_scene(CONTAINER, "fuzzed", Params())
APP = create_app(CONTAINER)
schema = schemathesis.openapi.from_dict(APP.openapi())
schema.app = APP

CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
    response_headers_conformance,
]

# A few derandomized examples per operation (`make fuzz` runs more).
FUZZED = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
)


def call(case: OpenApiCase, checks: list[Any]) -> None:
    """The case against the app with the admin token, in the scene that exists (past the 404 of
    an unknown scene)."""
    if case.path_parameters and "scene_id" in case.path_parameters:
        case.path_parameters["scene_id"] = SCENE.id
    case.call_and_validate(headers={"Authorization": f"Bearer {TOKEN}"}, checks=checks)


# The live feed never ends by itself, and the in-process client reads a whole answer: it is
# served by uvicorn in tests/service/test_event_stream.py (every parameter's 422 included).
STREAMED = ["/v1/scenes/{scene_id}/events/stream"]


@schema.exclude(path=STREAMED).parametrize()
@FUZZED
def test_no_server_error_and_every_answer_as_documented(case: OpenApiCase) -> None:
    call(case, CHECKS)


# Bodies whose validity JSON Schema cannot state whole, so that valid-by-schema data may be
# refused with a 422 naming the field: a scene's `params` (a partial tree checked against the
# method's parameters, with cross-field rules such as low < high), and frames (base64 images
# that must decode, rigid poses, masks the size of their image). Every bound of theirs that a
# schema can state is stated; their refusals are 422s naming the field (the test above).
# Likewise an appearance vector to compare, which must not be all zeros.
CONTENT_CHECKED = [
    "/v1/scenes",
    "/v1/scenes/{scene_id}/batches",
    "/v1/scenes/{scene_id}/inspections",
    "/v1/scenes/{scene_id}/objects/similar",
]
# Query parameters that exclude or need one another, which a schema cannot state: a seq or a
# time (`as_of` or `as_of_time`, `changed_since` or `changed_since_time`; both: a 422 naming
# the second), and a radius only around a point (`near`). Each case keeps the first alone.
EXCLUSIVE = (("as_of", "as_of_time"), ("changed_since", "changed_since_time"))


def one_of_each_pair(case: OpenApiCase) -> None:
    """The case's query without the parameters a schema-valid request may not combine."""
    query = case.query
    if not query:
        return
    for first, second in EXCLUSIVE:
        if first in query:
            query.pop(second, None)
    if "near" not in query:
        query.pop("radius", None)


# Deleting a scene needs `confirm` equal to the scene's id in the path, which no schema can
# state: any other valid string is a 422 naming `confirm` (tests/service/test_scene_lifecycle.py).
CONFIRMED = "/v1/scenes/{scene_id}"


@(
    schema.exclude(method="POST", path=CONTENT_CHECKED)
    .exclude(method="DELETE", path=CONFIRMED)
    .exclude(path=STREAMED)
    .parametrize()
)
@FUZZED
def test_what_the_schema_calls_valid_is_accepted(case: OpenApiCase) -> None:
    one_of_each_pair(case)
    call(case, [not_a_server_error, positive_data_acceptance])
