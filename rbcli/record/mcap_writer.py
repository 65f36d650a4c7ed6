"""A chunked MCAP writer for large per-step messages: the file layout of the `mcap` library's Writer,
with a leaner message path and a choice of zstd level.

Why not `mcap.writer.Writer`: recording 1,000 bodies every step writes ~250 kB of messages per step,
and that Writer copies each message four times on its way to disk (into a BytesIO record builder, out
of it, the compressed chunk into another builder, out again) and compresses chunks with zstd's default
level 3, which alone costs ~0.65 ms per frame there (~0.33 GB/s on this data). Here a message is two
references (its 31-byte record head and its payload) until the chunk is joined once; the chunk is
compressed at ZSTD_LEVEL; the compressed bytes go straight to the file.

Everything that is not a message is framed by the library's own record classes (`mcap.records`), and
the layout follows the MCAP specification (https://mcap.dev/spec) as the library's Writer lays it out:

    magic, Header, data section [Schema and Channel records inside the chunk where they are registered;
    Chunk + one MessageIndex per channel of the chunk; Attachment and Metadata records between chunks],
    DataEnd, summary section [Schema, Channel, Statistics, ChunkIndex, AttachmentIndex, MetadataIndex
    groups], SummaryOffset records (one per group), Footer (with the summary CRC), magic.

With `background=True` (what SinkMcap uses) the file work — joining a chunk, its CRC, compression and
every write — runs in one worker thread, in submission order, while the caller encodes the next
messages: zstd, zlib's CRC and file writes release the GIL, so on a second core they overlap the
encoding. The bytes are the same either way (each chunk is still compressed alone, in order); at most
MAX_PENDING chunks wait, so memory stays bounded, and a worker's error is raised in the caller at its
next call.

Durability (what a killed or crashed run leaves, docs/robustness.md "Crashes"): every file task ends by
flushing the stream to the operating system, so a process killed (SIGKILL, a crash) loses nothing that a
task wrote, and each chunk is self-contained, so a non-seeking reader recovers every chunk written before
the cut (`mcap_recovery.read_mcap_prefix`). With `fsync_seconds` set (SinkMcap: FSYNC_SECONDS), the file is
also fsynced after a task when the last fsync is that old, so a power cut or kernel crash loses at most
that much wall time of written chunks. `flush_chunk()` closes the open chunk early (SinkMcap does so at the
end of every block of frames, so no frame waits in the open chunk for the next block).

Chunks carry the CRC-32 of their uncompressed records; the data-section CRC is 0 ("not computed"), as
the library writes it by default. The tests read every file back with the `mcap` library's readers
(indexed and linear, CRCs validated) and compare it with the library Writer's file of the same messages.
"""

from __future__ import annotations

import os
import struct
import time
import zlib
from collections import defaultdict, deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import IO, Any

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
# zstd level 1: 0.64 GB/s and 0.73 of the size on rbsim state + transforms, against level 3's 0.33 GB/s
# and 0.53 (measured on a 4 MB chunk of a 1,000-body recording); a recording is written far more often
# than it is archived, and `zstd -19` can recompress an archive later.
ZSTD_LEVEL = 1
COMPRESSIONS = ("zstd", "lz4", "none")
MAX_PENDING = 2  # file tasks queued for the background worker before the caller waits
# Schema and channel ids are uint16 in MCAP (spec: Schema.id, Channel.id, Message.channel_id); schema id 0
# means "no schema" and ids here start at 1, so a file holds at most 65,535 of each.
MAX_ID = 0xFFFF

# Message record: opcode, content length | channel_id u16, sequence u32, log_time u64, publish_time u64
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED = _MESSAGE_HEAD.size - 9  # content bytes before the payload
_OP_MESSAGE = int(Opcode.MESSAGE)
_NO_TIME = 2**64  # a chunk's start time before its first message
# Chunk record up to its compression string: opcode, length | start u64, end u64, uncompressed size u64,
# uncompressed crc u32
_CHUNK_HEAD = struct.Struct("<BQQQQI")


def _record(record: McapRecord) -> bytes:
    """The bytes of one record framed by the mcap library's record class."""
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


def _check_id(kind: str, new_id: int) -> None:
    """Refuse an id MCAP cannot hold, before any byte of it is written (else struct.error mid-record)."""
    if new_id > MAX_ID:
        raise ValueError(
            f"an MCAP file holds at most {MAX_ID:,} {kind}s ({kind} ids are 16-bit); this is {kind} {new_id:,}"
        )


class McapChunkWriter:
    """Writes an MCAP file to a binary stream; the calls mirror `mcap.writer.Writer`'s.

    compression: "zstd" (at ZSTD_LEVEL), "lz4" or "none"; chunk_size: uncompressed bytes per chunk;
    background: do the file work in a worker thread; fsync_seconds: fsync the file after a file task
    when the last fsync is at least this old (None: never; the stream is flushed after every task
    either way). See the module docstring.
    """

    def __init__(
        self,
        stream: IO[bytes],
        *,
        compression: str = "zstd",
        chunk_size: int = 4 * 1024 * 1024,
        background: bool = False,
        fsync_seconds: float | None = None,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
        self._stream = stream
        self._compression = compression
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL) if compression == "zstd" else None
        self._chunk_size = chunk_size
        self._offset = 0  # bytes written to the stream
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = defaultdict(int)
        self._time_range: tuple[int, int] | None = None  # of the written chunks
        # the open chunk: its records (message heads and payloads by reference), size, per-channel
        # (log_time, offset) index and time range
        self._chunk_parts: list[bytes] = []
        self._chunk_bytes = 0
        self._chunk_index: dict[int, list[tuple[int, int]]] = defaultdict(list)
        self._chunk_start, self._chunk_end = _NO_TIME, -1
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="rbsim-mcap") if background else None
        self._pending: deque[Future[None]] = deque()
        self._fsync_seconds = fsync_seconds
        self._synced_at = time.monotonic()

    # --- the file ------------------------------------------------------------------------------------

    def _write(self, data: bytes | memoryview) -> None:
        """Append to the file (in the worker when there is one: only file tasks call this)."""
        self._stream.write(data)
        self._offset += len(data)

    def _task(self, fn: Callable[..., None], *args: Any) -> None:
        """Run a file task now, or queue it for the worker (waiting while MAX_PENDING are queued)."""
        if self._pool is None:
            self._run_task(fn, *args)
            return
        while self._pending and (self._pending[0].done() or len(self._pending) >= MAX_PENDING):
            self._pending.popleft().result()  # raises a failed task's error here
        self._pending.append(self._pool.submit(self._run_task, fn, *args))

    def _run_task(self, fn: Callable[..., None], *args: Any) -> None:
        """A file task, then its bytes handed to the operating system (and fsynced when due)."""
        fn(*args)
        flush = getattr(self._stream, "flush", None)
        if flush is not None:
            flush()
        if self._fsync_seconds is not None and time.monotonic() - self._synced_at >= self._fsync_seconds:
            fileno = getattr(self._stream, "fileno", None)
            if fileno is not None:
                os.fsync(fileno())
            self._synced_at = time.monotonic()

    def flush_chunk(self) -> None:
        """Close the open chunk now (it is written by a file task like a full one)."""
        self._finish_chunk()

    def _drain(self) -> None:
        """Wait for every queued file task; raise the first failure."""
        try:
            while self._pending:
                self._pending.popleft().result()
        finally:
            for future in self._pending:
                future.cancel()
            self._pending.clear()

    def start(self, profile: str = "", library: str = "") -> None:
        self._task(self._write, MAGIC + _record(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema's id (1, 2, ...); ValueError past MAX_ID (the file is left as it was)."""
        _check_id("schema", len(self._schemas) + 1)
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._add_to_chunk(_record(schema))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict | None = None) -> int:
        """A new channel's id (1, 2, ...); ValueError past MAX_ID (the file is left as it was)."""
        _check_id("channel", len(self._channels) + 1)
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels[channel.id] = channel
        self._add_to_chunk(_record(channel))
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        # the hot path of a recording (three calls per frame): plain comparisons, no tuples
        size = len(data)
        offset = self._chunk_bytes
        self._chunk_index[channel_id].append((log_time, offset))
        parts = self._chunk_parts
        parts.append(
            _MESSAGE_HEAD.pack(_OP_MESSAGE, _MESSAGE_FIXED + size, channel_id, sequence, log_time, publish_time)
        )
        parts.append(data)
        self._chunk_bytes = offset + _MESSAGE_HEAD.size + size
        self._counts[channel_id] += 1
        if log_time < self._chunk_start:
            self._chunk_start = log_time
        if log_time > self._chunk_end:
            self._chunk_end = log_time
        if self._chunk_bytes >= self._chunk_size:
            self._finish_chunk()

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        record = _record(
            Attachment(create_time=create_time, log_time=log_time, name=name, media_type=media_type, data=data)
        )

        def write() -> None:
            index = AttachmentIndex(
                offset=self._offset,
                length=len(record),
                log_time=log_time,
                create_time=create_time,
                data_size=len(data),
                name=name,
                media_type=media_type,
            )
            self._write(record)
            self._attachment_indexes.append(index)

        self._task(write)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        record = _record(Metadata(name=name, metadata=dict(data)))

        def write() -> None:
            self._metadata_indexes.append(MetadataIndex(offset=self._offset, length=len(record), name=name))
            self._write(record)

        self._task(write)

    def finish(self) -> None:
        """Write the open chunk, the summary and the footer (the stream is left open); after a file task
        failed, raise its error (the file is then incomplete)."""
        try:
            self._finish_chunk()
            self._drain()
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True)
        self._write(_record(DataEnd(data_section_crc=0)))
        summary_start = self._offset
        groups: list[tuple[Opcode, list[bytes]]] = [
            (Opcode.SCHEMA, [_record(s) for s in self._schemas.values()]),
            (Opcode.CHANNEL, [_record(c) for c in self._channels.values()]),
            (Opcode.STATISTICS, [_record(self._statistics())]),
            (Opcode.CHUNK_INDEX, [_record(i) for i in self._chunk_indexes]),
            (Opcode.ATTACHMENT_INDEX, [_record(i) for i in self._attachment_indexes]),
            (Opcode.METADATA_INDEX, [_record(i) for i in self._metadata_indexes]),
        ]
        summary, offsets, position = [], [], summary_start
        for opcode, records in groups:
            length = sum(len(r) for r in records)
            summary += records
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=position, group_length=length))
            position += length
        summary_offset_start = position
        summary += [_record(o) for o in offsets]
        summary_bytes = b"".join(summary)
        # the footer's CRC covers the summary and summary offset sections and the footer's first fields
        footer_head = struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start)
        crc = zlib.crc32(footer_head, zlib.crc32(summary_bytes))
        self._write(summary_bytes)
        footer = Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc)
        self._write(_record(footer))
        self._write(MAGIC)

    # --- chunks --------------------------------------------------------------------------------------

    def _new_chunk(self) -> None:
        self._chunk_parts = []
        self._chunk_bytes = 0
        self._chunk_index = defaultdict(list)
        self._chunk_start, self._chunk_end = _NO_TIME, -1

    def _add_to_chunk(self, record: bytes) -> None:
        self._chunk_parts.append(record)
        self._chunk_bytes += len(record)

    def _finish_chunk(self) -> None:
        """Hand the open chunk to a file task and start a new one."""
        if not self._chunk_bytes:
            return
        times = (self._chunk_start, self._chunk_end) if self._chunk_end >= 0 else None
        if times is not None:
            start, end = self._time_range or times
            self._time_range = (min(start, times[0]), max(end, times[1]))
        self._task(self._write_chunk, self._chunk_parts, self._chunk_index, times)
        self._new_chunk()

    def _write_chunk(
        self, parts: list[bytes], message_index: dict[int, list[tuple[int, int]]], times: tuple[int, int] | None
    ) -> None:
        """A file task: the Chunk record, its MessageIndex records, and its ChunkIndex for the summary."""
        records = b"".join(parts)
        if self._zstd is not None:
            name, data = "zstd", self._zstd.compress(records)
        elif self._compression == "lz4":
            name, data = "lz4", lz4.frame.compress(records)
        else:
            name, data = "", records
        start, end = times or (0, 0)
        tail = struct.pack("<I", len(name)) + name.encode() + struct.pack("<Q", len(data))
        content = _CHUNK_HEAD.size - 9 + len(tail) + len(data)
        head = _CHUNK_HEAD.pack(Opcode.CHUNK, content, start, end, len(records), zlib.crc32(records))
        chunk_start = self._offset
        self._write(head + tail)
        self._write(data)
        chunk_length = self._offset - chunk_start
        index_offsets, index_start = {}, self._offset
        for channel_id in sorted(message_index):
            entries = np.asarray(message_index[channel_id], dtype="<u8").tobytes()
            record = struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + len(entries), channel_id, len(entries))
            index_offsets[channel_id] = self._offset
            self._write(record + entries)
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=index_offsets,
                message_index_length=self._offset - index_start,
                compression=name,
                compressed_size=len(data),
                uncompressed_size=len(records),
            )
        )

    def _statistics(self) -> Statistics:
        start, end = self._time_range or (0, 0)
        return Statistics(
            message_count=sum(self._counts.values()),
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=start,
            message_end_time=end,
            channel_message_counts=dict(self._counts),
        )
