"""rbcli.record.mcap_writer against the MCAP specification as the `mcap` library reads and writes it.

Each file is read back with the library's indexed (SeekingReader) and linear (NonSeekingReader) readers
with CRC validation, its footer CRC is recomputed here from the specification, and its content is
compared with the file the library's own Writer makes of the same calls.
"""

import io
import struct
import zlib

import numpy as np
import pytest
import zstandard
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Chunk, ChunkIndex, Footer, MessageIndex
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from rbcli.record.mcap_writer import MAGIC, McapChunkWriter

LIBRARY_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def _script(writer, seed=0):
    """The same calls for either writer: two schemas, three channels (one never used), messages of
    varied sizes over several chunks and out of time order, an attachment and metadata in between."""
    rng = np.random.default_rng(seed)
    writer.start(profile="test", library="test-lib")
    s1 = writer.register_schema("a.A", "protobuf", b"schema-a")
    s2 = writer.register_schema("b.B", "jsonschema", b'{"type": "object"}')
    c1 = writer.register_channel("/one", "protobuf", s1, {"k": "v"})
    c2 = writer.register_channel("/two", "json", s2)
    writer.add_attachment(5, 6, "scene.yaml", "application/yaml", b"name: x\n")
    for k in range(300):
        size = int(rng.integers(0, 5000))
        t = 1_000 * k - (2_500 if k % 7 == 3 else 0)  # a few messages earlier than the two before them
        writer.add_message(c1 if k % 3 else c2, t, rng.bytes(size), t + 1, k)
        if k == 150:
            writer.add_metadata("middle", {"a": "1", "b": "2"})
    writer.register_channel("/unused", "protobuf", s1)
    writer.add_metadata("end", {"status": "ok"})
    writer.finish()


def _ours(compression, chunk_size=64 * 1024, background=False):
    buf = io.BytesIO()
    _script(McapChunkWriter(buf, compression=compression, chunk_size=chunk_size, background=background))
    return buf.getvalue()


def _library(compression, chunk_size=64 * 1024):
    buf = io.BytesIO()
    _script(Writer(buf, compression=LIBRARY_COMPRESSION[compression], chunk_size=chunk_size))
    return buf.getvalue()


def _content(data, reader_class):
    reader = reader_class(io.BytesIO(data), validate_crcs=True)
    found = reader.iter_messages(log_time_order=False)
    messages = [(ch.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, ch, m in found]
    return messages, reader


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_readers_see_what_the_library_writer_would_have_written(compression):
    ours, theirs = _ours(compression), _library(compression)
    assert _ours(compression, background=True) == ours  # the worker thread changes no byte
    assert ours[:8] == MAGIC and ours[-8:] == MAGIC
    for reader_class in (SeekingReader, NonSeekingReader):
        got, reader = _content(ours, reader_class)
        want, reference = _content(theirs, reader_class)
        assert got == want and len(got) == 300, reader_class.__name__
    summary, expected = SeekingReader(io.BytesIO(ours)).get_summary(), SeekingReader(io.BytesIO(theirs)).get_summary()
    assert summary.schemas == expected.schemas and summary.channels == expected.channels
    stats, want_stats = summary.statistics, expected.statistics
    for name in ("message_count", "schema_count", "channel_count", "attachment_count", "metadata_count",
                 "message_start_time", "message_end_time", "channel_message_counts"):  # fmt: skip
        assert getattr(stats, name) == getattr(want_stats, name), name
    assert stats.chunk_count == len(summary.chunk_indexes) > 3  # the script spans several chunks
    assert {c.compression for c in summary.chunk_indexes} == {"" if compression == "none" else compression}
    ours_reader, their_reader = SeekingReader(io.BytesIO(ours)), SeekingReader(io.BytesIO(theirs))
    assert list(ours_reader.iter_attachments()) == list(their_reader.iter_attachments())
    assert list(ours_reader.iter_metadata()) == list(their_reader.iter_metadata())
    assert ours_reader.get_header() == their_reader.get_header()
    # indexed reading in log-time order (uses chunk indexes, message indexes and the chunk time ranges)
    ordered = [m.log_time for _, _, m in ours_reader.iter_messages(log_time_order=True)]
    assert ordered == sorted(ordered) and len(ordered) == 300


def test_indexes_point_at_the_records_they_name():
    data = _ours("zstd")
    records = list(StreamReader(io.BytesIO(data), skip_magic=False, validate_crcs=True).records)
    footer = records[-1]
    assert isinstance(footer, Footer)
    # the footer CRC covers the summary and summary offset sections and the footer's first two fields
    head = struct.pack("<BQQQ", 0x02, 20, footer.summary_start, footer.summary_offset_start)
    summary_end = len(data) - 8 - (9 + 20)
    assert footer.summary_crc == zlib.crc32(head, zlib.crc32(data[footer.summary_start : summary_end]))
    summary = SeekingReader(io.BytesIO(data)).get_summary()
    for index in summary.chunk_indexes:
        assert isinstance(index, ChunkIndex)
        chunk = next(
            StreamReader(io.BytesIO(data[index.chunk_start_offset :]), skip_magic=True, emit_chunks=True).records
        )
        assert isinstance(chunk, Chunk) and chunk.compression == index.compression == "zstd"
        records = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        times = []
        for channel_id, offset in index.message_index_offsets.items():
            message_index = next(StreamReader(io.BytesIO(data[offset:]), skip_magic=True).records)
            assert isinstance(message_index, MessageIndex) and message_index.channel_id == channel_id
            for log_time, at in message_index.records:  # each entry points at its Message record
                opcode, _, channel, _, stamp = struct.unpack_from("<BQHIQ", records, at)
                assert (opcode, channel, stamp) == (0x05, channel_id, log_time)
                times.append(log_time)
        assert (index.message_start_time, index.message_end_time) == (min(times), max(times))
    for attachment in summary.attachment_indexes:
        assert data[attachment.offset] == 0x09 and attachment.data_size == 8
    for metadata in summary.metadata_indexes:
        assert data[metadata.offset] == 0x0C


def test_a_file_without_messages_is_valid():
    buf = io.BytesIO()
    writer = McapChunkWriter(buf)
    writer.start()
    writer.register_schema("a.A", "protobuf", b"x")
    writer.finish()
    messages, reader = _content(buf.getvalue(), NonSeekingReader)
    assert messages == [] and SeekingReader(io.BytesIO(buf.getvalue())).get_summary().statistics.message_count == 0


def test_a_corrupted_chunk_is_caught_by_its_crc():
    data = bytearray(_ours("none"))
    index = SeekingReader(io.BytesIO(bytes(data))).get_summary().chunk_indexes[1]
    data[index.chunk_start_offset + index.chunk_length - 100] ^= 0xFF  # a payload byte inside the chunk
    with pytest.raises(Exception, match="crc"):
        _content(bytes(data), SeekingReader)


def test_unknown_compression_is_refused():
    with pytest.raises(ValueError, match="gzip"):
        McapChunkWriter(io.BytesIO(), compression="gzip")


class _FailingStream(io.BytesIO):
    def write(self, data):
        if self.tell() > 100_000:
            raise OSError("disk full")
        return super().write(data)


@pytest.mark.parametrize("background", [False, True])
def test_a_failing_write_reaches_the_caller(background):
    with pytest.raises(OSError, match="disk full"):
        _script(McapChunkWriter(_FailingStream(), compression="none", chunk_size=16 * 1024, background=background))
