"""A typed Python client of the PBD-AG HTTP API (sync and asyncio, on httpx).

    from pbdag_client import Client, build_batch, build_frame, detection

Requests and answers are the `api_schema` models; error answers raise the typed exceptions of
`pbdag_client.errors` (each a `PbdagError`, the root of the project's one hierarchy, from
`pbdag_errors`); `pbdag_client.encoding` turns numpy depth images and boolean masks into the
wire's png16 depth and COCO RLE. It needs api_schema, pbdag_errors, httpx, numpy and pillow only.
"""

from pbdag_client.async_client import AsyncClient
from pbdag_client.client import Client
from pbdag_client.encoding import (
    build_batch,
    build_frame,
    detection,
    encode_depth_f32,
    encode_depth_png16,
    encode_mask,
    rle_runs,
    rle_string,
)
from pbdag_client.errors import (
    AccessDenied,
    ApiError,
    BadRequest,
    BatchDead,
    BatchTimeout,
    Conflict,
    Forbidden,
    InsufficientStorage,
    InvalidRequest,
    PayloadTooLarge,
    PbdagError,
    RateLimited,
    RequestRefused,
    ResourceNotFound,
    ServerError,
    Unauthorized,
)
from pbdag_client.routes import DEFAULT_TIMEOUT_S, Submitted, scenes_called

__all__ = [
    "DEFAULT_TIMEOUT_S",
    "AccessDenied",
    "ApiError",
    "AsyncClient",
    "BadRequest",
    "BatchDead",
    "BatchTimeout",
    "Client",
    "Conflict",
    "Forbidden",
    "InsufficientStorage",
    "InvalidRequest",
    "PayloadTooLarge",
    "PbdagError",
    "RateLimited",
    "RequestRefused",
    "ResourceNotFound",
    "ServerError",
    "Submitted",
    "Unauthorized",
    "build_batch",
    "build_frame",
    "detection",
    "encode_depth_f32",
    "encode_depth_png16",
    "encode_mask",
    "rle_runs",
    "rle_string",
    "scenes_called",
]
