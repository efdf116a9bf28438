"""Synchronous commands (scenes, verdicts, baselines, inspections): decide on the head, append.

They share the worker's write path (the unit of work). A concurrent append by the worker or
another request moves the head, and the command is decided again on the new head (optimistic
concurrency, `UnitOfWork.on_the_head`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

from core.baseline import BaselinePackage, decide_load
from core.events import Event, SceneRenamed
from core.params import Params
from core.state import SceneState
from core.values import BaselineSource
from service.bootstrap import Container
from service.store.event_log import SceneRecord
from service.store.unit_of_work import Appended, Writes


def run_command(
    container: Container, scene_id: str, decide_command: Callable[[SceneState], Sequence[Event]]
) -> tuple[list[Event], Appended]:
    """Decide on the current head and append; decided again when the head moved meanwhile.
    A refused command (a domain error) propagates: nothing is appended."""

    def append(
        work: Writes, state: SceneState, events: list[Event]
    ) -> tuple[list[Event], Appended]:
        return events, work.append(scene_id, state, events)

    return container.uow.on_the_head(scene_id, lambda state: list(decide_command(state)), append)


def create_scene(
    container: Container,
    name: str,
    params: Params,
    package: BaselinePackage | None = None,
    source: BaselineSource | None = None,
) -> SceneRecord:
    """A scene; from a baseline package (a later session in the same house), event 0 names the
    package and event 1 loads its fixtures, in one transaction."""
    with container.uow.begin() as work:
        record, state = work.create_scene(name, params, baseline=source)
        if package is None:
            return record
        appended = work.append(record.id, state, decide_load(package))
    assert appended.seqs is not None
    return replace(record, head_seq=appended.seqs[1])


def rename_scene(container: Container, scene_id: str, name: str) -> Appended:
    """Record the scene's new name in its log (`scene_renamed`); the scene row follows in the
    same transaction. The name is part of the log (event 0 records it, the state folds it), so
    a rename is an event replay applies, never an update of the row alone: `pbdag rebuild` and
    every replay agree with the row. The same name again appends nothing."""

    def decide(state: SceneState) -> list[Event]:
        return [] if state.name == name else [SceneRenamed(name=name)]

    return run_command(container, scene_id, decide)[1]
