"""`pbdag ingest folder|rosbag`: import recorded frames, with a detector plugin's masks, into a
scene of a running service (added to `pbdag` through the pbdag.commands entry point)."""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path

from ingest.frames import FrameSource, IngestError, one_line
from ingest.sink import SinkError

DEFAULT_URL = "http://127.0.0.1:8000"
# The `ingest` extra of pyproject.toml: the module each of its distributions installs.
INGEST_EXTRA = {"rosbags": "rosbags", "yaml": "pyyaml", "tqdm": "tqdm"}


def missing_ingest_extra() -> list[str]:
    """The distributions of the `ingest` extra that are not installed."""
    return [
        name for module, name in INGEST_EXTRA.items() if importlib.util.find_spec(module) is None
    ]


def needs_ingest_extra(
    handler: Callable[[argparse.Namespace], int],
) -> Callable[[argparse.Namespace], int]:
    """The handler, run only when the `ingest` extra is installed (else one line saying so); an
    input or service error ends it with one line (control characters escaped) and status 2."""

    def checked(args: argparse.Namespace) -> int:
        missing = missing_ingest_extra()
        if missing:
            print(
                f"pbdag ingest: needs the ingest extra (missing {', '.join(missing)}): "
                "pip install 'pbdag[ingest]'",
                file=sys.stderr,
            )
            return 2
        try:
            return handler(args)
        except (IngestError, SinkError) as error:
            print(f"pbdag ingest: error: {one_line(str(error))}", file=sys.stderr)
            return 2

    return checked


class DefaultsFormatter(argparse.HelpFormatter):
    """Help that shows an option's default when it has a value worth showing."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        help_text = action.help or ""
        if action.default in (None, False, [], argparse.SUPPRESS) or "%(default)" in help_text:
            return help_text
        return f"{help_text} (default: %(default)s)"


def register(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add `ingest` to the `pbdag` command."""
    ingest = commands.add_parser(
        "ingest", help="import a recorded folder or ROS 2 bag into a scene of a running service"
    )
    sources = ingest.add_subparsers(dest="source", required=True, help="what the recording is")

    folder = sources.add_parser(
        "folder",
        help="a 7-Scenes/TUM-like folder: frame-NNNNNN.depth.png, .pose.txt, camera-intrinsics.txt",
        formatter_class=DefaultsFormatter,
    )
    folder.add_argument("path", type=Path, metavar="PATH", help="the folder")
    folder.add_argument(
        "--fps", type=float, default=30.0, help="frame rate that turns frame numbers into times"
    )
    _common_options(folder)
    folder.set_defaults(handler=needs_ingest_extra(_run_folder))

    rosbag = sources.add_parser(
        "rosbag",
        help="a ROS 2 bag (sqlite3 or mcap): depth Image, CameraInfo, pose from /tf or odometry",
        formatter_class=DefaultsFormatter,
    )
    rosbag.add_argument("bag", type=Path, metavar="BAG", help="the bag's folder")
    rosbag.add_argument(
        "--depth-topic",
        required=True,
        help="sensor_msgs/Image: 16UC1 (see --depth-scale) or 32FC1 (m)",
    )
    rosbag.add_argument("--camera-info-topic", required=True, help="sensor_msgs/CameraInfo")
    pose = rosbag.add_mutually_exclusive_group(required=True)
    pose.add_argument("--tf", action="store_true", help="pose from /tf and /tf_static")
    pose.add_argument("--odom-topic", help="pose from this nav_msgs/Odometry topic")
    rosbag.add_argument("--map-frame", help="with --tf: the world frame (e.g. map)")
    rosbag.add_argument(
        "--camera-frame",
        help="the camera's optical frame (z forward); default: the depth images' frame_id",
    )
    rosbag.add_argument(
        "--camera-in-base",
        nargs=7,
        type=float,
        metavar=("X", "Y", "Z", "QX", "QY", "QZ", "QW"),
        help="with --odom-topic: the camera's pose in the odometry's child frame "
        "(default: from /tf_static)",
    )
    rosbag.add_argument(
        "--label-topic", help="label-image detector: the instance-label sensor_msgs/Image topic"
    )
    rosbag.add_argument(
        "--pose-tolerance",
        type=float,
        default=0.05,
        help="seconds between a depth stamp and its pose",
    )
    rosbag.add_argument(
        "--sync-tolerance",
        type=float,
        default=0.02,
        help="seconds between a depth stamp and its detector topics' messages",
    )
    _common_options(rosbag)
    rosbag.set_defaults(handler=needs_ingest_extra(_run_rosbag))


def _common_options(parser: argparse.ArgumentParser) -> None:
    """Options both sources share: where to send, the detector, which frames."""
    parser.add_argument("--scene", required=True, help="scene id or name (created when new)")
    parser.add_argument("--url", default=DEFAULT_URL, help="the service")
    parser.add_argument("--token", help="bearer token with the write scope (default: $PBDAG_TOKEN)")
    parser.add_argument(
        "--detector", help="detector plugin (pbdag.detectors entry point); none: depth only"
    )
    parser.add_argument("--labels", type=Path, help="label map (JSON or YAML): id -> class")
    parser.add_argument("--masks", type=Path, help="instance-pngs detector: the PNG folder")
    parser.add_argument(
        "--detector-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an option for the detector plugin (repeatable), e.g. pattern={index:06d}.png",
    )
    parser.add_argument(
        "--depth-scale", type=float, default=0.001, help="metres per unit of 16-bit depth"
    )
    parser.add_argument("--stride", type=int, default=1, help="take every Nth frame")
    parser.add_argument(
        "--limit", type=int, help="only the first N frames the stride takes (skipped ones count)"
    )
    parser.add_argument(
        "--frames-per-batch",
        type=int,
        default=8,
        help="frames per batch (the service takes at most PBDAG_MAX_FRAMES_PER_BATCH, 16)",
    )
    parser.add_argument("--batch-prefix", help="batch ids' prefix (default: the recording's name)")
    parser.add_argument("--wait", action="store_true", help="wait until every batch is processed")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _detector_options(args: argparse.Namespace) -> dict[str, str]:
    """The detector's options: the named flags, then every --detector-option KEY=VALUE."""
    options = {}
    for name in ("labels", "masks", "label_topic"):
        value = getattr(args, name, None)
        if value is not None:
            options[name.replace("_", "-")] = str(value)
    for item in args.detector_option:
        key, equals, value = item.partition("=")
        if not equals or not key:
            raise IngestError(f"--detector-option {item!r} is not KEY=VALUE")
        options[key] = value
    return options


def _run(args: argparse.Namespace, source: FrameSource) -> int:
    """Load the detector, ingest, print the summary."""
    from ingest.detectors import load_detector
    from ingest.pipeline import ingest

    if not 1 <= args.frames_per_batch <= 1000:
        raise IngestError(
            f"--frames-per-batch must be between 1 and 1000, got {args.frames_per_batch}"
        )
    detector = None
    if args.detector is not None:
        detector = load_detector(args.detector, _detector_options(args))
    elif args.labels or args.masks or getattr(args, "label_topic", None):
        raise IngestError("--labels, --masks and --label-topic need a --detector")
    summary = ingest(
        source,
        detector,
        url=args.url,
        scene=args.scene,
        token=args.token or os.environ.get("PBDAG_TOKEN"),
        frames_per_batch=args.frames_per_batch,
        wait=args.wait,
        prefix=args.batch_prefix,
        progress=not args.no_progress,
    )
    print("\n".join(summary.lines()))
    dead = summary.sink is not None and bool(summary.sink.errors)
    return 1 if dead or summary.frames_sent == 0 else 0


def _run_folder(args: argparse.Namespace) -> int:
    """`pbdag ingest folder`."""
    from ingest.folder import FolderSource

    source = FolderSource(
        args.path,
        depth_scale=args.depth_scale,
        stride=args.stride,
        limit=args.limit,
        fps=args.fps,
    )
    return _run(args, source)


def _run_rosbag(args: argparse.Namespace) -> int:
    """`pbdag ingest rosbag`."""
    from ingest.rosbag import OdomPose, RosbagSource, TfPose
    from ingest.transforms import rigid

    pose: TfPose | OdomPose
    if args.tf:
        if not args.map_frame:
            raise IngestError("--tf needs --map-frame (the world frame, e.g. map)")
        if args.camera_in_base is not None:
            raise IngestError("--camera-in-base goes with --odom-topic, not --tf")
        pose = TfPose(map_frame=args.map_frame, camera_frame=args.camera_frame)
    else:
        if args.map_frame:
            raise IngestError("--map-frame goes with --tf; odometry poses are in its frame")
        extrinsic = None
        if args.camera_in_base is not None:
            values = args.camera_in_base
            try:
                extrinsic = rigid(values[:3], values[3:])
            except ValueError as error:  # a zero quaternion
                raise IngestError(f"--camera-in-base: {error}") from error
        pose = OdomPose(
            topic=args.odom_topic, camera_in_base=extrinsic, camera_frame=args.camera_frame
        )
    source = RosbagSource(
        args.bag,
        depth_topic=args.depth_topic,
        camera_info_topic=args.camera_info_topic,
        pose=pose,
        depth_scale=args.depth_scale,
        stride=args.stride,
        limit=args.limit,
        pose_tolerance=args.pose_tolerance,
        sync_tolerance=args.sync_tolerance,
    )
    return _run(args, source)
