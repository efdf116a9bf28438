"""Synchronous commands (verdicts, baselines, inspections): decide on the head, append, project.

They share the worker's append path; a concurrent append by the worker or another request
moves the head, and the command is decided again on the new head (optimistic concurrency).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from core.baseline import decide_load
from core.events import Event
from core.evolve import fold
from core.params import Params
from core.state import SceneState
from service.bootstrap import Container
from service.errors import Conflict
from service.store.engine import write_transaction
from service.store.errors import ConcurrencyConflict
from service.store.event_log import SceneRecord
from service.store.projection import project_append

ATTEMPTS = 5


def run_command(
    container: Container, scene_id: str, decide_command: Callable[[SceneState], Sequence[Event]]
) -> tuple[SceneState, list[Event], tuple[int, int] | None]:
    """Decide on the current head and append; retried when the head moved meanwhile."""
    for _attempt in range(ATTEMPTS):
        state = container.log.load_state(scene_id)
        new_events = list(decide_command(state))  # domain errors propagate: nothing appended
        new_state = fold(state, new_events)
        try:
            with write_transaction(container.engine) as connection:
                seqs = container.log.append(connection, scene_id, state.head_seq, new_events)
                if seqs is not None:
                    project_append(
                        connection,
                        container.log,
                        scene_id,
                        state,
                        new_events,
                        new_state,
                        seqs[0],
                        container.settings.snapshot_interval,
                    )
            return new_state, new_events, seqs
        except ConcurrencyConflict:
            continue
    raise Conflict(f"scene {scene_id!r} kept changing; try again")


def create_scene_from_baseline(
    container: Container, name: str, params: Params, package: dict[str, Any], source: dict[str, Any]
) -> SceneRecord:
    """A later session in the same house: event 0 names the package, event 1 loads its fixtures."""
    loaded = decide_load(package)
    with write_transaction(container.engine) as connection:
        record, created = container.log.insert_scene(connection, name, params, baseline=source)
        state = fold(SceneState(), [created])
        new_state = fold(state, loaded)
        seqs = container.log.append(connection, record.id, 0, loaded)
        assert seqs is not None
        project_append(
            connection,
            container.log,
            record.id,
            state,
            loaded,
            new_state,
            seqs[0],
            container.settings.snapshot_interval,
        )
    return replace(record, head_seq=seqs[1])
