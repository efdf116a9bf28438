"""PostgreSQL's LISTEN/NOTIFY as an early wake-up of the event streams, never their source.

Every append on PostgreSQL notifies `EVENTS_CHANNEL` with the scene's id, delivered when its
transaction commits (the append's head update does, in service/store/append_sql.py). Each API
process holds one listening connection, in a thread (`Wakeups`), and wakes the streams of that
scene waiting in its event loop. A stream still reads its events from the log and still polls
it: a notification lost (the listener reconnecting, a process that started after the commit)
only delays an event to the next poll.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from typing import Any

import anyio
import sqlalchemy as sa

EVENTS_CHANNEL = "pbdag_events"
LISTEN_TIMEOUT_S = 0.5  # how soon the listener sees that it should stop
RECONNECT_S = 1.0

logger = logging.getLogger("pbdag.feed")


class Wakeups:
    """One LISTEN connection per process, opened by the first stream that waits, and the streams
    waiting on it, scene by scene."""

    def __init__(self, engine: sa.Engine) -> None:
        self.engine = engine
        self._waiting: dict[str, set[tuple[asyncio.AbstractEventLoop, asyncio.Event]]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, name="pbdag-listen", daemon=True)

    def start(self) -> None:
        """Start listening, once (the first stream does; a process serving none listens not)."""
        with self._lock:
            if not self._thread.is_alive() and not self._stop.is_set():
                self._thread.start()

    def close(self) -> None:
        """Stop listening and close the connection (within LISTEN_TIMEOUT_S)."""
        with self._lock:
            self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10)

    async def wait(self, scene_id: str, timeout_s: float) -> None:
        """Until `scene_id`'s log grows or `timeout_s` passed, whichever comes first."""
        self.start()
        waiter = (asyncio.get_running_loop(), asyncio.Event())
        with self._lock:
            self._waiting.setdefault(scene_id, set()).add(waiter)
        try:
            with anyio.move_on_after(timeout_s):
                await waiter[1].wait()
        finally:
            with self._lock:
                waiters = self._waiting.get(scene_id, set())
                waiters.discard(waiter)
                if not waiters:
                    self._waiting.pop(scene_id, None)

    def wake(self, scene_id: str) -> None:
        """Wake the streams of `scene_id` (from any thread)."""
        with self._lock:
            waiters = list(self._waiting.get(scene_id, ()))
        for loop, event in waiters:
            if not loop.is_closed():
                loop.call_soon_threadsafe(event.set)

    def _listen(self) -> None:
        while not self._stop.is_set():
            try:
                self._listen_once()
            except Exception as error:  # the database away: the streams poll meanwhile
                logger.warning("event notifications unavailable (%s); retrying", error)
                self._stop.wait(RECONNECT_S)

    def _listen_once(self) -> None:
        # A connection of its own, out of the pool: it stays in LISTEN until the process ends.
        pooled = self.engine.raw_connection()
        driver: Any = pooled.driver_connection  # the psycopg connection
        pooled.detach()
        try:
            driver.autocommit = True
            driver.execute(f"LISTEN {EVENTS_CHANNEL}")
            while not self._stop.is_set():
                for notice in driver.notifies(timeout=LISTEN_TIMEOUT_S):
                    self.wake(notice.payload)
        finally:
            pooled.close()
