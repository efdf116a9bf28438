"""Scene states for reads: the nearest cached state or snapshot at or before the seq, plus the tail."""

from __future__ import annotations

import threading
from collections import OrderedDict

from core.evolve import fold
from core.state import SceneState
from service.store.errors import SeqOutOfRange
from service.store.event_log import EventLog


class StateReader:
    """`state(scene, as_of)`; states are immutable per (scene, seq), so caching them is safe."""

    # A cached state at most this many events below the target beats a snapshot plus its tail.
    MAX_CACHED_TAIL = 2000

    def __init__(self, log: EventLog, capacity: int = 32) -> None:
        self.log = log
        self.capacity = capacity
        self._cache: OrderedDict[tuple[str, int], SceneState] = OrderedDict()
        self._lock = threading.Lock()

    def state(self, scene_id: str, as_of: int | None = None) -> SceneState:
        """The scene's state at `as_of` (default its head)."""
        head = self.log.scene(scene_id).head_seq
        target = head if as_of is None else as_of
        if target < 0 or target > head:
            raise SeqOutOfRange(f"as_of {target} is outside 0..{head}")
        with self._lock:
            exact = self._cache.get((scene_id, target))
            if exact is not None:
                self._cache.move_to_end((scene_id, target))
                return exact
            nearest = max(
                (seq for (scene, seq) in self._cache if scene == scene_id and seq < target),
                default=None,
            )
            base = None if nearest is None else self._cache[(scene_id, nearest)]
        if base is not None and target - base.head_seq <= self.MAX_CACHED_TAIL:
            tail = self.log.read(scene_id, after=base.head_seq, up_to=target)
            state = fold(base, (event.to_core() for event in tail))
        else:
            state = self.log.load_state(scene_id, target)
        with self._lock:
            self._cache[(scene_id, target)] = state
            while len(self._cache) > self.capacity:
                self._cache.popitem(last=False)
        return state

    def forget(self, scene_id: str) -> None:
        """Drop the scene's cached states (it was deleted). A state is never served from the
        cache without the scene's row read first, so a deleted scene is a 404 even in another
        process's reader; this frees the memory, and keeps a scene later created under the
        same id from meeting the old one's states."""
        with self._lock:
            for key in [key for key in self._cache if key[0] == scene_id]:
                del self._cache[key]
