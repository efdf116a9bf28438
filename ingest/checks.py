"""Checks of a recording's pieces, so that a bad one is reported before anything is sent: image
sizes (read from a PNG's header, before any pixel is decoded), poses, intrinsics, files kept
inside the recording's folder, and small text matrices read without quoting them.

The bounds are the service's. An image side is at most `MAX_IMAGE_SIDE` pixels, the wire's own
bound (`api_schema.requests.MAX_IMAGE_SIDE`), so an image has at most `MAX_IMAGE_PIXELS` pixels
(Pillow's decompression-bomb threshold lies above it). A pose passes the service's rigid-transform
check, with its tolerances. Intrinsics pass the wire's `Intrinsics` model, and their principal
point lies inside the image.

Problems are plain sentences that never quote a file's content; `frame_error` makes one line of
the frame, the file and the fix out of them.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
from PIL import Image
from pydantic import ValidationError

from api_schema import requests
from ingest.frames import CameraIntrinsics, IngestError, one_line
from pbdag_errors import Refused

MAX_IMAGE_SIDE = requests.MAX_IMAGE_SIDE
MAX_IMAGE_PIXELS = MAX_IMAGE_SIDE * MAX_IMAGE_SIDE
# The service's rigid-pose tolerances (its decoder, which `ingest` does not import, holds them):
# real pose sources drift from orthonormal by about 1e-4, a scale or shear error by far more.
POSE_LAST_ROW_ATOL = 1e-6
ROTATION_ATOL = 1e-3
# Pose and intrinsics files hold a few numbers; anything larger is not one of them.
MAX_TEXT_BYTES = 64 * 1024
TOO_LARGE_FIX = (
    f"downscale the recording to at most {MAX_IMAGE_SIDE} pixels a side "
    "(and its intrinsics with it)"
)


class BadFile(Refused):
    """A file that cannot be used: `problem` says why without quoting it, `fix` (if given) what
    to do instead of the caller's usual fix. The caller turns it into an IngestError naming the
    frame and the file."""

    def __init__(self, problem: str, fix: str | None = None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.fix = fix


def frame_error(frame: str, where: object, problem: str, fix: str) -> IngestError:
    """One line: the frame (e.g. `frame 9`), the file or bag topic, what is wrong, the fix."""
    return IngestError(one_line(f"{frame}: {where}: {problem}; fix: {fix}"))


def bad_file_error(frame: str, where: object, bad: BadFile, fix: str) -> IngestError:
    """`frame_error` of a BadFile, with its own fix when it has one."""
    return frame_error(frame, where, bad.problem, bad.fix or fix)


def library_reason(error: BaseException) -> str:
    """What a library says went wrong: the class and the first line of its message (later lines
    of parser messages quote the input), at most 160 characters."""
    lines = str(error).strip().splitlines()
    first = one_line(lines[0]) if lines else ""
    if len(first) > 160:
        first = first[:157] + "..."
    return f"{type(error).__name__}: {first}" if first else type(error).__name__


def image_size_problem(width: int, height: int) -> str | None:
    """Why an image of this size is refused (no pixels, or over the limit), or None."""
    if width <= 0 or height <= 0:
        return f"the image is {width} x {height} pixels, it has none"
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        return (
            f"the image is {width} x {height} pixels, over the limit of {MAX_IMAGE_SIDE} x "
            f"{MAX_IMAGE_SIDE} ({MAX_IMAGE_PIXELS} pixels) per image"
        )
    return None


def pose_problem(pose: npt.NDArray[np.float64]) -> str | None:
    """Why `pose` is no 4x4 finite rigid transform (rotation and translation), or None."""
    if pose.shape != (4, 4):
        return f"the pose is a {' x '.join(map(str, pose.shape))} matrix, not 4 x 4"
    if not np.isfinite(pose).all():
        return "the pose holds NaN or infinite values"
    if not np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=POSE_LAST_ROW_ATOL):
        return "the pose's last row is not 0 0 0 1 (it is no rigid transform)"
    rotation = pose[:3, :3]
    deviation = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if deviation > ROTATION_ATOL:
        return (
            f"the pose's rotation is not orthonormal (max |R^T R - I| = {deviation:.3g}, "
            f"tolerance {ROTATION_ATOL:g}): a scale or shear is no rigid transform"
        )
    if float(np.linalg.det(rotation)) < 0:
        return "the pose's rotation is a reflection (determinant -1), not a rotation"
    return None


def intrinsics_problem(intrinsics: CameraIntrinsics) -> str | None:
    """Why these intrinsics are refused: the image size, the wire's bounds on the focal lengths
    and principal point (finite, focal lengths 1 to 100000 px), the principal point outside the
    image; or None."""
    size = image_size_problem(intrinsics.width, intrinsics.height)
    if size is not None:
        return size
    try:
        intrinsics.wire()
    except ValidationError as error:
        first = error.errors()[0]
        name = ".".join(str(part) for part in first["loc"])
        return f"{name} is outside the service's bounds: {first['msg'].lower()}"
    for name, value, side in (
        ("cx", intrinsics.cx, intrinsics.width),
        ("cy", intrinsics.cy, intrinsics.height),
    ):
        if not 0 <= value <= side:
            return f"the principal point's {name} lies outside the image (0 to {side} px)"
    return None


def outside_problem(path: Path, root: Path) -> str | None:
    """Why `path` is not a file of the folder `root` (a symbolic link leads out of it, or loops),
    or None. The link's target is not named."""
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError):
        return "is a symbolic link that loops"
    if not resolved.is_relative_to(root.resolve()):
        return "resolves outside the folder (a symbolic link leads out of it)"
    return None


def read_matrix(path: Path, rows: int, columns: int) -> npt.NDArray[np.float64]:
    """A `rows` x `columns` matrix of numbers from a small text file (whitespace between numbers,
    `#` starts a comment); BadFile when it is none."""
    if not path.is_file():
        raise BadFile("is not a regular file")
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_TEXT_BYTES + 1)
    except OSError as error:
        raise BadFile(f"cannot be read ({error.strerror})") from error
    if len(raw) > MAX_TEXT_BYTES:
        raise BadFile(f"is larger than {MAX_TEXT_BYTES} bytes, no {rows}x{columns} matrix")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise BadFile("is not text") from error
    values: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        try:
            values.append([float(field) for field in fields])
        except ValueError:
            raise BadFile(f"line {number} holds something that is not a number") from None
    lengths = [len(row) for row in values]
    if lengths != [columns] * rows:
        found = f"{len(values)} line" + ("" if len(values) == 1 else "s")
        per_line = ", ".join(map(str, lengths)) or "none"
        raise BadFile(
            f"expected {rows} lines of {columns} numbers, found {found} "
            f"(numbers per line: {per_line})"
        )
    return np.array(values, dtype=np.float64)


@contextlib.contextmanager
def open_png(path: Path) -> Iterator[Image.Image]:
    """The PNG at `path` with only its header read, its size checked against the limit (no pixel
    is decoded); BadFile when it is no regular file, no PNG, or too large."""
    if not path.is_file():
        raise BadFile("is not a regular file")
    try:
        with warnings.catch_warnings():
            # Pillow warns, then refuses, above its own threshold: both are over our limit.
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(path, formats=["PNG"])
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as error:
        raise BadFile(
            f"the image has more than {Image.MAX_IMAGE_PIXELS} pixels, over the limit of "
            f"{MAX_IMAGE_SIDE} x {MAX_IMAGE_SIDE} per image",
            TOO_LARGE_FIX,
        ) from error
    except Exception as error:  # Pillow reports unreadable files through many types
        raise BadFile(f"is not a PNG image ({type(error).__name__})") from error
    with image:
        problem = image_size_problem(image.width, image.height)
        if problem is not None:
            raise BadFile(problem, TOO_LARGE_FIX)
        yield image
