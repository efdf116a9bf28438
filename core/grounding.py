"""Grounded observations (section 3.2): each object mask's valid depth becomes a 3D proposal."""

from __future__ import annotations

from collections.abc import Sequence

from core.geometry import Proposal, ground_detection
from core.observation import Frame
from core.params import Params


def ground_frame(frame: Frame, params: Params) -> list[Proposal]:
    """Object proposals of one frame; masks with too little valid depth are rejected."""
    proposals = []
    for index, detection in enumerate(frame.detections):
        if detection.kind != "object":
            continue  # fixture masks feed the voxel map instead
        proposal = ground_detection(
            detection,
            frame,
            params.proposal,
            params.visibility.min_range_m,
            params.visibility.max_range_m,
            index,
        )
        if proposal is not None:
            proposals.append(proposal)
    return proposals


def ground_frames(frames: Sequence[Frame], params: Params) -> tuple[tuple[Proposal, ...], ...]:
    """The object proposals of each frame of a batch, in frame order."""
    return tuple(tuple(ground_frame(frame, params)) for frame in frames)
