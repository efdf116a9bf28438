"""`pbdag repair`: a scene whose log holds an unreadable event is quarantined and rebuilt.

Events are never edited. An older version could store an event with a non-finite number (as
null), and no fold can read past it; a correction event appended later could not help, because
every event after the bad one was decided on the state it poisoned. So the repair:

1. finds the first event that does not decode or fold;
2. creates a new scene with the same name (plus " (repaired)") and parameters, and copies the
   events before it, with the same seqs and batch ids (they were decided on a sound state);
3. moves the batches: those whose events all lie before the bad event are recorded as done in
   the new scene, every later or unfinished batch is queued there again, in arrival order, so
   today's validation and method decide them anew (a batch that cannot be applied is parked
   dead with a `batch_skipped` event, as always);
4. quarantines the old scene, naming the new one: its log stays readable as evidence
   (`GET /events`), its state is not served, and it takes no writes.

Commands after the bad event (verdicts, baselines, inspections) are not replayed: they were
answers to a state that was wrong. The report counts them so an operator can redo them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from core.events import Event
from core.evolve import fold
from core.params import Params
from core.state import SceneState
from service.bootstrap import Container
from service.store.errors import UnreadableEvent
from service.store.event_log import StoredEvent


@dataclass
class RepairReport:
    """What `repair_scene` found and did."""

    scene_id: str
    bad_seq: int | None = None
    reason: str | None = None
    new_scene_id: str | None = None
    events_copied: int = 0
    batches_done: int = 0
    batches_requeued: int = 0
    commands_dropped: list[int] = field(default_factory=list)  # seqs of commands after the bad one

    @property
    def healthy(self) -> bool:
        """True when every event of the scene decodes and folds."""
        return self.bad_seq is None


def first_unreadable(stored: Sequence[StoredEvent]) -> tuple[int, str, list[Event]] | None:
    """(seq, reason, the readable events before it) of the first event that does not decode or
    fold, or None when the whole log is sound."""
    state, readable = SceneState(), list[Event]()
    for row in stored:
        try:
            event = row.to_core()
            state = fold(state, [event])
        except UnreadableEvent as error:
            return row.seq, error.reason, readable
        except (KeyError, ValueError, TypeError) as error:
            return row.seq, f"{type(error).__name__}: {error}", readable
        readable.append(event)
    return None


def repair_scene(container: Container, scene_id: str) -> RepairReport:
    """Quarantine a scene with an unreadable event and rebuild it as a new scene (see above)."""
    report = RepairReport(scene_id)
    scene = container.log.scene(scene_id)
    stored = list(container.log.iter_events(scene_id))
    found = first_unreadable(stored)
    if found is None:
        return report
    report.bad_seq, report.reason, readable = found
    report.commands_dropped = [
        row.seq for row in stored if row.seq >= report.bad_seq and row.batch_id is None
    ]
    batch_of = {row.seq: row.batch_id for row in stored}
    records = container.queue.of_scene(scene_id)
    with container.uow.begin() as work:
        name = scene.name if scene.name.endswith("(repaired)") else f"{scene.name} (repaired)"
        record, state = work.create_scene(name, Params.from_dict(scene.params))
        # Copy the sound prefix batch by batch, so each keeps its seqs and its batch id.
        run: list[Event] = []
        for seq, event in enumerate(readable[1:], start=1):  # seq 0 is the new scene's own
            run.append(event)
            if seq + 1 == report.bad_seq or batch_of.get(seq + 1) != batch_of[seq]:
                state = work.append(record.id, state, run, batch_id=batch_of[seq]).state
                report.events_copied += len(run)
                run = []
        for batch in records:
            sound = batch.status == "done" and (
                batch.last_seq is None or batch.last_seq < report.bad_seq
            )
            container.queue.copy_into(work.connection, record.id, batch, done=sound)
            report.batches_done += sound
            report.batches_requeued += not sound
        container.queue.retire_scene(work.connection, scene_id, f"moved to scene {record.id}")
        container.log.quarantine(
            work.connection,
            scene_id,
            f"event {report.bad_seq} cannot be read ({report.reason}); repaired as scene {record.id}",
        )
    report.new_scene_id = record.id
    return report
