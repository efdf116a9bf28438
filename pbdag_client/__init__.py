"""A typed Python client of the PBD-AG HTTP API (sync and asyncio, on httpx).

    from pbdag_client import Client, build_batch, build_frame, detection

Requests and answers are the `api_schema` models; error answers raise the typed exceptions of
`pbdag_client.errors`; `pbdag_client.encoding` turns numpy depth images and boolean masks into
the wire's png16 depth and COCO RLE. It needs api_schema, httpx, numpy and pillow only.
"""

from pbdag_client.client import DEFAULT_TIMEOUT_S, AsyncClient, Client, Submitted
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
    BadRequest,
    BatchDead,
    BatchTimeout,
    Conflict,
    Forbidden,
    InsufficientStorage,
    InvalidRequest,
    NotFound,
    PayloadTooLarge,
    PbdagError,
    RateLimited,
    ServerError,
    Unauthorized,
)

__all__ = [
    "DEFAULT_TIMEOUT_S",
    "AccessDenied",
    "AsyncClient",
    "BadRequest",
    "BatchDead",
    "BatchTimeout",
    "Client",
    "Conflict",
    "Forbidden",
    "InsufficientStorage",
    "InvalidRequest",
    "NotFound",
    "PayloadTooLarge",
    "PbdagError",
    "RateLimited",
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
]
