"""Operator commands: `pbdag rebuild`, `pbdag requeue`, `pbdag repair`, `pbdag gc`,
`pbdag export`, `pbdag blobs migrate`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from pbdag_errors import PbdagError
from service.settings import Settings

if TYPE_CHECKING:
    from service.bootstrap import Container
    from service.store.event_log import EventLog

GC_LISTED = 20  # batches `pbdag gc` names one per line; the rest are counted


def register(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the operator commands to `pbdag`."""
    rebuild = commands.add_parser(
        "rebuild",
        help="drop every projection, rebuild it from the log, report differences per scene",
    )
    rebuild.add_argument("--scene", action="append", help="only these scenes (repeatable)")
    rebuild.set_defaults(handler=_rebuild)

    requeue = commands.add_parser(
        "requeue", help="put dead batches back in the queue (they apply at their turn)"
    )
    requeue.add_argument("--scene", required=True, help="the scene")
    which = requeue.add_mutually_exclusive_group(required=True)
    which.add_argument("--batch", action="append", help="a dead batch id (repeatable)")
    which.add_argument("--all-dead", action="store_true", help="every dead batch of the scene")
    requeue.set_defaults(handler=_requeue)

    repair = commands.add_parser(
        "repair",
        help="quarantine a scene whose log holds an unreadable event and rebuild it as a new scene",
    )
    repair.add_argument("scene", help="the scene to check and, if needed, repair")
    repair.set_defaults(handler=_repair)

    gc = commands.add_parser(
        "gc",
        help="delete the raw bodies of batches older than PBDAG_RAW_RETENTION (events stay); "
        "safe while the service runs",
    )
    gc.add_argument(
        "--dry-run", action="store_true", help="report what would be deleted; change nothing"
    )
    gc.add_argument(
        "--retention",
        help="override PBDAG_RAW_RETENTION for this run (e.g. 7d, 12h, 3600)",
    )
    gc.set_defaults(handler=_gc)

    export = commands.add_parser(
        "export",
        help="write a scene's published graph as GraphML or node-link JSON (the same graph as "
        "GET /v1/scenes/{id}/graph?format=...)",
    )
    export.add_argument("scene", help="the scene")
    export.add_argument(
        "--format", choices=("graphml", "json-graph"), default="graphml", help="(default: graphml)"
    )
    export.add_argument("--as-of", type=int, help="the graph at this seq (default: the head)")
    export.add_argument(
        "--all", action="store_true", help="every track, not only the published ones"
    )
    export.add_argument("--out", type=Path, help="write to this file (default: standard output)")
    export.set_defaults(handler=_export)

    blobs = commands.add_parser("blobs", help="the raw batches' storage")
    blob_commands = blobs.add_subparsers(
        dest="blobs_command", required=True, help="what to do with the raw batches"
    )
    migrate = blob_commands.add_parser(
        "migrate",
        help="copy every blob the queue names from the other backend to this one, checked by "
        "sha256 (idempotent; run it again to resume)",
        description="Copy every blob the queue names (except those `pbdag gc` collected) into "
        "the backend --to from the other one "
        "(the folder PBDAG_DATA_DIR/blobs, or the database's blobs table), each checked by its "
        "sha256 before and after. Blobs already in the target intact are skipped, so a second run "
        "resumes an interrupted one. Stop the API and the workers first, then start them with "
        "PBDAG_BLOB_BACKEND set to the target. The source is left as it was.",
    )
    migrate.add_argument(
        "--to",
        required=True,
        choices=("postgres", "folder"),
        dest="target",
        help="the backend to copy into: the database's blobs table, or PBDAG_DATA_DIR/blobs",
    )
    migrate.set_defaults(handler=_blobs_migrate)


def _rebuild(args: argparse.Namespace) -> int:
    from service.cli_support import open_container

    container = open_container()
    try:
        return _rebuild_scenes(container.log, args.scene)
    finally:
        container.engine.dispose()  # its pool's connections closed, not left to the collector


def _rebuild_scenes(log: EventLog, only: list[str] | None) -> int:
    from service.store.projection import rebuild_scene

    quarantined = {scene.id for scene in log.scenes() if scene.quarantined}
    scene_ids = only or [scene.id for scene in log.scenes()]
    failed = False
    for scene_id in scene_ids:  # one scene's failure never stops the others
        if scene_id in quarantined:
            print(f"{scene_id}: quarantined (see `pbdag repair`); skipped")
            continue
        try:
            report = rebuild_scene(log, scene_id)
        except PbdagError as error:
            print(f"{scene_id}: FAILED: {error.detail}")
            failed = True
            continue
        except Exception as error:
            print(f"{scene_id}: FAILED: {type(error).__name__}: {error}")
            failed = True
            continue
        differences = (
            ""
            if report.identical
            else f" (tracks {report.tracks_differ}, snapshots {report.snapshots_differ}, "
            f"baselines {report.baselines_differ}"
            f"{', the name' if report.name_differs else ''})"
        )
        verdict = "identical" if report.identical else "DIFFERED"
        reencoded = (
            f"; {report.snapshots_reencoded} snapshots in an older format rewritten"
            if report.snapshots_reencoded
            else ""
        ) + (
            f"; {report.tracks_reencoded} tracks rewritten with the fields added since"
            if report.tracks_reencoded
            else ""
        )
        print(
            f"{scene_id}: {report.events} events replayed; projections {verdict}{differences}"
            f"{reencoded}"
        )
        failed |= not report.identical
    print("rebuild: some scenes differed or failed" if failed else "rebuild: no difference")
    return 1 if failed else 0


def _requeue(args: argparse.Namespace) -> int:
    from service.cli_support import open_container

    container = open_container()
    dead = [record for record in container.queue.of_scene(args.scene) if record.status == "dead"]
    collected = [record.batch_id for record in dead if record.blob_collected_at is not None]
    if not args.batch and collected:
        print(
            f"scene {args.scene}: {len(collected)} dead batches cannot be requeued, their raw "
            "bodies were deleted by `pbdag gc`"
        )
    batch_ids = args.batch or [
        record.batch_id for record in dead if record.blob_collected_at is None
    ]
    if not batch_ids:
        print(f"scene {args.scene}: no dead batch")
        return 0
    code = 0
    for batch_id in batch_ids:
        try:
            container.queue.requeue(args.scene, batch_id)
            print(f"{args.scene}/{batch_id}: queued again")
        except PbdagError as error:
            print(f"{args.scene}/{batch_id}: {error.detail}", file=sys.stderr)
            code = 1
    return code


def _repair(args: argparse.Namespace) -> int:
    from service.cli_support import open_container
    from service.repair import repair_scene

    container = open_container()
    try:
        report = repair_scene(container, args.scene)
    except PbdagError as error:
        print(f"pbdag repair: {error.detail}", file=sys.stderr)
        return 2
    if report.healthy:
        print(f"{args.scene}: every event reads and folds; nothing to repair")
        return 0
    print(
        f"{args.scene}: event {report.bad_seq} cannot be read ({report.reason}).\n"
        f"  quarantined; repaired as scene {report.new_scene_id}: {report.events_copied} events "
        f"copied, {report.batches_done} batches kept as done, {report.batches_requeued} queued "
        "again (a worker decides them anew)"
    )
    if report.commands_dropped:
        print(
            f"  commands after the bad event were not replayed (seqs {report.commands_dropped}); "
            "issue them again on the new scene if still wanted"
        )
    return 0


def _gc(args: argparse.Namespace) -> int:
    from service.cli_support import open_container
    from service.retention import collect
    from service.settings import parse_duration

    container = open_container()
    retention = container.settings.raw_retention
    if args.retention is not None:
        try:
            retention = parse_duration(args.retention)
        except ValueError as error:
            print(f"pbdag gc: --retention: {error}", file=sys.stderr)
            return 2
    if retention is None:
        print("pbdag gc: PBDAG_RAW_RETENTION is unset, so every raw batch is kept; nothing removed")
        return 0
    report = collect(container, retention, dry_run=args.dry_run)
    verb = "would remove" if args.dry_run else "removed"
    print(
        f"pbdag gc: {verb} the raw bodies of {report.batches} batches, {report.bytes_freed} bytes "
        f"(finished more than {retention:g} s ago; events are kept)"
    )
    for record in report.expired[:GC_LISTED]:
        print(f"  {record.scene_id}/{record.batch_id}: {record.blob_bytes} bytes ({record.status})")
    if len(report.expired) > GC_LISTED:
        print(f"  ... and {len(report.expired) - GC_LISTED} more")
    if report.kept_referenced:
        print(
            f"pbdag gc: kept {len(report.kept_referenced)} expired batches holding the frame of "
            "a pending verification or an unresolved inspection:"
        )
        for record in report.kept_referenced[:GC_LISTED]:
            print(f"  {record.scene_id}/{record.batch_id}")
    for scene_id, reason in report.unreadable_scenes.items():
        print(f"pbdag gc: scene {scene_id} kept whole, its state cannot be read: {reason}")
    if not args.dry_run:
        print(f"pbdag gc: {report.blobs_deleted} blobs deleted from the blob store")
    swept = (report.swept_collected, report.swept_unnamed, report.swept_leftovers)
    if any(swept):
        print(
            f"pbdag gc: the sweep {verb} {swept[0]} blobs of batches collected earlier, "
            f"{swept[1]} blobs that no batch names and {swept[2]} leftovers of interrupted writes"
        )
    return 0


def _export(args: argparse.Namespace) -> int:
    from core.graph import publish
    from service.cli_support import open_container
    from service.export import export_graph
    from service.states import StateReader
    from service.store.errors import SceneQuarantined

    container = open_container()
    try:
        scene = container.log.scene(args.scene)
        if scene.quarantined is not None:
            raise SceneQuarantined(scene.id, scene.quarantined)
        state = StateReader(container.log).state(scene.id, args.as_of)
    except PbdagError as error:
        print(f"pbdag export: {error.detail}", file=sys.stderr)
        return 2
    graph = publish(state, include_all=args.all)
    graph.graph["scene_id"] = scene.id
    document = export_graph(graph, args.format)
    if args.out is None:
        sys.stdout.buffer.write(document)
        sys.stdout.flush()
    else:
        args.out.write_bytes(document)
        print(
            f"{scene.id}: {graph.number_of_nodes()} nodes, {graph.number_of_edges()} edges "
            f"at seq {state.head_seq} -> {args.out}",
            file=sys.stderr,
        )
    return 0


def _blobs_migrate(args: argparse.Namespace) -> int:
    from service.cli_support import load_settings, open_container
    from service.store.engine import is_postgres

    settings = load_settings()
    container = open_container(settings.model_copy(update={"blob_backend": "folder"}))
    try:
        if not is_postgres(container.engine):
            print(
                "pbdag blobs migrate: the database is not PostgreSQL (PBDAG_DATABASE_URL); on "
                f"{container.engine.dialect.name} blobs can only live in the folder",
                file=sys.stderr,
            )
            return 2
        return _copy_blobs(container, settings, args.target)
    finally:
        container.engine.dispose()


def _copy_blobs(container: Container, settings: Settings, to: str) -> int:
    from service.blob_migration import migrate_blobs
    from service.store.blobs import FileBlobStore, PgBlobStore

    folder = FileBlobStore(settings.data_dir / "blobs")
    table = PgBlobStore(container.engine)
    source, target = (folder, table) if to == "postgres" else (table, folder)
    where = {"folder": f"the folder {folder.root.resolve()}", "postgres": "the database"}
    keys = container.queue.blob_keys()
    came_from = "folder" if to == "postgres" else "postgres"
    print(f"blobs migrate: {len(keys)} blobs named by the queue, {where[came_from]} -> {where[to]}")
    report = migrate_blobs(keys, source, target, progress=lambda line: print(line, flush=True))
    print(
        f"blobs migrate: {report.copied} copied ({report.bytes_copied / 1e6:.1f} MB), "
        f"{report.already_there} already there, {len(report.missing)} missing, "
        f"{len(report.corrupt)} not matching their sha256, in {report.seconds:.1f} s"
    )
    for key in report.missing:
        print(f"  missing in both backends: {key}", file=sys.stderr)
    for key in report.corrupt:
        print(f"  not matching its sha256 in the source: {key}", file=sys.stderr)
    if report.complete:
        print(f"blobs migrate: done; run the fleet with PBDAG_BLOB_BACKEND={to}")
        return 0
    return 1
