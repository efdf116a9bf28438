"""`pbdag scenes list|rename|delete`: the scenes of the database, renamed or deleted in place.

Like the other operator commands they work on the database directly (what `PATCH` and `DELETE
/v1/scenes/{id}` do, without a running service or a token). An unknown scene is one line and
exit 1; a name the text rule refuses is one line and exit 2. Deleting a scene is the one
exception to the append-only log (service/store/scene_deletion.py): `delete` asks for the
scene's id to be typed again unless `--yes`.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from pbdag_errors import PbdagError

if TYPE_CHECKING:
    from service.bootstrap import Container

__all__ = ["register"]


def register(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add `scenes` and its subcommands to the `pbdag` parser."""
    scenes = commands.add_parser("scenes", help="list, rename and delete scenes")
    actions = scenes.add_subparsers(
        dest="scenes_command", required=True, help="what to do with scenes"
    )

    listing = actions.add_parser(
        "list", help="every scene, oldest first: id, name, head seq, created, quarantined, queued"
    )
    listing.set_defaults(handler=_list)

    rename = actions.add_parser(
        "rename", help="rename a scene (a `scene_renamed` event in its log)"
    )
    rename.add_argument("id", metavar="ID", help="the scene's id, the first column of the list")
    rename.add_argument("name", metavar="NAME", help="the new name (printable, 1-200 characters)")
    rename.set_defaults(handler=_rename)

    delete = actions.add_parser(
        "delete",
        help="delete a scene and everything it holds: its log, projections, queue rows and "
        "raw batches (cannot be undone)",
    )
    delete.add_argument("id", metavar="ID", help="the scene's id, the first column of the list")
    delete.add_argument(
        "--yes", action="store_true", help="do not ask for the id to be typed again"
    )
    delete.set_defaults(handler=_delete)


def _container() -> Container:
    from service.cli_support import open_container

    return open_container()


def _list(_args: argparse.Namespace) -> int:
    from service.store.queue_records import UNFINISHED

    container = _container()
    try:
        scenes = container.log.scenes()
        if not scenes:
            print("no scenes")
            return 0
        print(
            f"{'id':<16}  {'name':<24} {'head':>7}  {'created (UTC)':<20} {'quarantined':<11} "
            "queued"
        )
        for scene in scenes:
            counts = container.queue.counts(scene.id)
            queued = sum(counts.get(status, 0) for status in UNFINISHED)
            print(
                f"{scene.id:<16}  {scene.name:<24} {scene.head_seq:>7}  "
                f"{_when(scene.created_at):<20} {'yes' if scene.quarantined else 'no':<11} "
                f"{queued}"
            )
        return 0
    finally:
        container.engine.dispose()


def _rename(args: argparse.Namespace) -> int:
    import pydantic

    from api_schema import SceneRename
    from service.commands import rename_scene
    from service.store.errors import SceneQuarantined

    try:
        name = SceneRename(name=args.name).name
    except pydantic.ValidationError as error:
        print(f"pbdag scenes rename: NAME: {error.errors()[0]['msg']}", file=sys.stderr)
        return 2
    container = _container()
    try:
        scene = container.log.scene(args.id)
        if scene.quarantined is not None:
            raise SceneQuarantined(scene.id, scene.quarantined)
        appended = rename_scene(container, scene.id, name)
    except PbdagError as error:
        print(f"pbdag scenes rename: {error.detail}", file=sys.stderr)
        return 1
    finally:
        container.engine.dispose()
    if appended.seqs is None:
        print(f"{scene.id}: already named {name!r}; nothing appended")
    else:
        print(f"{scene.id}: renamed {scene.name!r} -> {name!r} (seq {appended.seqs[0]})")
    return 0


def _delete(args: argparse.Namespace) -> int:
    from service.store.scene_deletion import delete_scene

    container = _container()
    try:
        scene = container.log.scene(args.id)
        if not args.yes and not _confirmed(scene.id, scene.name):
            print("pbdag scenes delete: not confirmed; nothing deleted", file=sys.stderr)
            return 1
        deleted = delete_scene(container.engine, container.blobs, scene.id)
    except PbdagError as error:
        print(f"pbdag scenes delete: {error.detail}", file=sys.stderr)
        return 1
    finally:
        container.engine.dispose()
    print(
        f"{deleted.scene_id}: deleted {deleted.events} events, {deleted.batches} batches, "
        f"{deleted.blobs} raw batch blobs ({deleted.bytes} bytes), {deleted.tracks} tracks, "
        f"{deleted.snapshots} snapshots, {deleted.baselines} baselines"
    )
    return 0


def _confirmed(scene_id: str, name: str) -> bool:
    """Whether the operator typed the scene's id again (end of input: no)."""
    print(
        f"delete scene {scene_id} ({name}) and everything it holds? This cannot be undone.",
        file=sys.stderr,
    )
    print(f"type {scene_id} to confirm: ", end="", file=sys.stderr, flush=True)
    typed = sys.stdin.readline() if sys.stdin is not None else ""
    return typed.strip() == scene_id


def _when(timestamp: float) -> str:
    return datetime.fromtimestamp(timestamp, UTC).strftime("%Y-%m-%d %H:%M:%S")
