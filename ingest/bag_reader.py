"""A ROS 2 bag opened for reading with the `rosbags` library: its topics' connections, checked,
and their messages. A bag that cannot be opened, read or deserialised is one IngestError naming
the bag and the topic, whatever the library, sqlite3 or the decompressor raised; a file of the
bag's folder that a symbolic link leads out of it is refused before anything is opened."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_typestore

from ingest.checks import library_reason, outside_problem
from ingest.frames import IngestError, one_line

BAG_FIX = "the bag is damaged or incomplete: copy it again, or record it again"


class BagReader:
    """An open bag (`path`, the `rosbags` reader) whose failures are one line each."""

    def __init__(self, path: Path, reader: AnyReader) -> None:
        self.path = path
        self.reader = reader
        self.connections: list[Connection] = list(reader.connections)

    def unreadable(self, what: str, error: Exception, frame: str | None = None) -> IngestError:
        """One line: the frame (if known), the bag, what could not be read, the library's
        reason, the fix."""
        where = f"{frame}: bag {self.path}" if frame else f"bag {self.path}"
        return IngestError(one_line(f"{where}: {what} ({library_reason(error)}); fix: {BAG_FIX}"))

    def connections_of(self, topic: str, msgtype: str, role: str) -> list[Connection]:
        """The connections of `topic`, checked to exist with the expected type."""
        found = [c for c in self.connections if c.topic == topic]
        if not found:
            topics = sorted({f"{c.topic} ({c.msgtype})" for c in self.connections})
            raise IngestError(
                f"{role} topic {topic!r} is not in bag {self.path}; its topics: {', '.join(topics)}"
            )
        wrong = sorted({c.msgtype for c in found if c.msgtype != msgtype})
        if wrong:
            raise IngestError(f"{role} topic {topic!r} has type {wrong[0]}, expected {msgtype}")
        return found

    def raw(
        self, connections: Sequence[Connection], topic: str, **window: int
    ) -> Iterator[tuple[Connection, int, bytes]]:
        """The serialised messages of `connections` (within `window`: start, stop ns)."""
        messages = self.reader.messages(connections, **window)
        while True:
            try:
                item = next(messages, None)
            except Exception as error:  # rosbags, sqlite3 and decompression errors alike
                raise self.unreadable(f"topic {topic} cannot be read", error) from error
            if item is None:
                return
            yield item

    def decoded(self, connection: Connection, raw: bytes, frame: str | None = None) -> Any:
        """One message (of `frame`, if it is a frame's) deserialised."""
        try:
            return self.reader.deserialize(raw, connection.msgtype)
        except Exception as error:  # the CDR decoder's struct, index and value errors
            what = f"a message of topic {connection.topic} cannot be deserialised"
            raise self.unreadable(what, error, frame) from error

    def messages(
        self, connections: Sequence[Connection], topic: str, **window: int
    ) -> Iterator[tuple[int, Any]]:
        """(bag time, message) of each message of `connections`, deserialised."""
        for connection, bag_time, raw in self.raw(connections, topic, **window):
            yield bag_time, self.decoded(connection, raw)


@contextlib.contextmanager
def open_bag(path: Path) -> Iterator[BagReader]:
    """The bag at `path` (a bag folder, or a file), open."""
    if path.is_dir():  # a bag folder: its files are read beside its metadata.yaml
        for entry in sorted(path.iterdir()):
            problem = outside_problem(entry, path)
            if problem is not None:
                raise IngestError(
                    one_line(
                        f"bag {path}: {entry.name} {problem}; fix: copy the file into the "
                        "bag's folder instead of linking to it"
                    )
                )
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as error:  # rosbags, sqlite3 and YAML errors alike
        message = f"bag {path}: it cannot be opened ({library_reason(error)}); fix: {BAG_FIX}"
        raise IngestError(one_line(message)) from error
    try:
        yield BagReader(path, reader)
    finally:
        reader.close()
