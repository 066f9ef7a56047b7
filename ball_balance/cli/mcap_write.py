"""An MCAP writer for `bag record` that never copies a message's bytes (plain Python, no ROS).

The files are laid out as rosbag2's MCAP storage writes them by default: chunked (768 KiB),
uncompressed, indexed (a message index per chunk and channel, a chunk index, schemas, channels,
statistics and metadata in the summary), so that readers can seek by time: `ros2 bag`,
rosbags, Foxglove, PlotJuggler and the `mcap` Python reader.

Why not the `mcap` package's writer (still used for reading): it builds every chunk in memory
buffers that grow as messages arrive and copies it twice more before the file, and checksums it.
For a 640x480 camera frame that costs milliseconds, and on a machine the simulated graph
loads it costs enough that the recorder drops frames. Here a message's bytes are handed to the
file object as they are (a large write bypasses its buffer), at a fraction of that cost. Chunks
carry no checksum (the format's 0: "not computed"), as rosbag2 writes none by default either;
the summary's is computed (it is small).

Record layouts: the MCAP specification (mcap.dev/spec), version 0.
"""
from __future__ import annotations

import struct
import zlib
from typing import BinaryIO, Dict, List, Tuple

MAGIC = b"\x89MCAP0\r\n"
CHUNK_SIZE_BYTES = 768 * 1024  # rosbag2's default MCAP chunk size

# record opcodes
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = range(0x01, 0x09)
STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 0x0B, 0x0C, 0x0D, 0x0E, 0x0F

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log time, publish time
_MESSAGE_FIELDS_BYTES = 2 + 4 + 8 + 8
_CHUNK_FIELDS_BYTES = 8 + 8 + 8 + 4 + 4 + 8  # start, end, uncompressed size, crc, compression "", records length


def _string(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack("<I", len(data)) + data


def _string_map(mapping: Dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in mapping.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


class _Chunk:
    """Messages waiting to be written as one chunk: their heads and data, not joined."""

    def __init__(self):
        self.pieces: List[bytes] = []
        self.records_bytes = 0
        self.start_ns, self.end_ns = 0, 0
        self.index: Dict[int, List[Tuple[int, int]]] = {}  # channel -> [(log time, offset in records)]

    def add(self, channel_id: int, sequence: int, log_ns: int, publish_ns: int, data: bytes) -> None:
        if not self.pieces:
            self.start_ns = self.end_ns = log_ns
        self.start_ns, self.end_ns = min(self.start_ns, log_ns), max(self.end_ns, log_ns)
        self.index.setdefault(channel_id, []).append((log_ns, self.records_bytes))
        head = _MESSAGE_HEAD.pack(MESSAGE, _MESSAGE_FIELDS_BYTES + len(data), channel_id, sequence & 0xFFFFFFFF,
                                  log_ns, publish_ns)
        self.pieces += (head, data)
        self.records_bytes += len(head) + len(data)


class McapWriter:
    """`start()`, `register_schema()`, `register_channel()`, `add_message()`, `add_metadata()`, `finish()`."""

    def __init__(self, stream: BinaryIO, chunk_size_bytes: int = CHUNK_SIZE_BYTES):
        self._stream, self._chunk_size_bytes = stream, chunk_size_bytes
        self._schemas: Dict[int, bytes] = {}   # id -> schema record
        self._channels: Dict[int, bytes] = {}  # id -> channel record
        self._chunk = _Chunk()
        self._chunk_indexes: List[bytes] = []
        self._metadata_indexes: List[bytes] = []
        self._message_counts: Dict[int, int] = {}
        self._start_ns, self._end_ns = None, 0
        # messages in the chunks handed to the file so far: what a write that fails later
        # (disk full) leaves readable, by a reader that scans the file
        self.messages_in_file = 0

    def _write(self, data: bytes) -> None:
        self._stream.write(data)

    def start(self, profile: str, library: str) -> None:
        self._write(MAGIC)
        self._write(_record(HEADER, _string(profile) + _string(library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema_id = len(self._schemas) + 1  # 0 means "no schema"
        record = _record(SCHEMA, struct.pack("<H", schema_id) + _string(name) + _string(encoding)
                         + struct.pack("<I", len(data)) + data)
        self._schemas[schema_id] = record
        self._write(record)  # in the data section too: a reader that scans needs it before the messages
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: Dict[str, str]) -> int:
        channel_id = len(self._channels)
        record = _record(CHANNEL, struct.pack("<HH", channel_id, schema_id) + _string(topic)
                         + _string(message_encoding) + _string_map(metadata))
        self._channels[channel_id] = record
        self._message_counts[channel_id] = 0
        self._write(record)
        return channel_id

    def add_message(self, channel_id: int, log_time: int, publish_time: int, data: bytes, sequence: int = 0) -> None:
        self._chunk.add(channel_id, sequence, log_time, publish_time, data)
        self._message_counts[channel_id] += 1
        self._start_ns = log_time if self._start_ns is None else min(self._start_ns, log_time)
        self._end_ns = max(self._end_ns, log_time)
        if self._chunk.records_bytes >= self._chunk_size_bytes:
            self._write_chunk()

    def add_metadata(self, name: str, data: Dict[str, str]) -> None:
        self._write_chunk()  # the metadata record goes between chunks
        offset = self._stream.tell()
        record = _record(METADATA, _string(name) + _string_map(data))
        self._write(record)
        self._metadata_indexes.append(_record(METADATA_INDEX, struct.pack("<QQ", offset, len(record)) + _string(name)))

    def _write_chunk(self) -> None:
        chunk = self._chunk
        if not chunk.pieces:
            return
        chunk_offset = self._stream.tell()
        chunk_body_bytes = _CHUNK_FIELDS_BYTES + chunk.records_bytes
        self._write(struct.pack("<BQQQQII", CHUNK, chunk_body_bytes, chunk.start_ns, chunk.end_ns,
                                chunk.records_bytes, 0, 0) + struct.pack("<Q", chunk.records_bytes))
        for piece in chunk.pieces:
            self._write(piece)
        index_start = self._stream.tell()
        offsets = {}
        for channel_id, entries in chunk.index.items():
            offsets[channel_id] = self._stream.tell()
            body = b"".join(struct.pack("<QQ", log_ns, at) for log_ns, at in entries)
            self._write(_record(MESSAGE_INDEX, struct.pack("<HI", channel_id, len(body)) + body))
        index_bytes = self._stream.tell() - index_start
        offsets_body = b"".join(struct.pack("<HQ", c, o) for c, o in offsets.items())
        self._chunk_indexes.append(_record(CHUNK_INDEX, struct.pack(
            "<QQQQ", chunk.start_ns, chunk.end_ns, chunk_offset, 1 + 8 + chunk_body_bytes)
            + struct.pack("<I", len(offsets_body)) + offsets_body + struct.pack("<Q", index_bytes)
            + _string("") + struct.pack("<QQ", chunk.records_bytes, chunk.records_bytes)))
        self.messages_in_file += len(chunk.pieces) // 2  # a head and the data per message
        self._chunk = _Chunk()

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", c, n) for c, n in self._message_counts.items())
        return _record(STATISTICS, struct.pack(
            "<QHIIIIQQ", sum(self._message_counts.values()), len(self._schemas), len(self._channels), 0,
            len(self._metadata_indexes), len(self._chunk_indexes), self._start_ns or 0, self._end_ns)
            + struct.pack("<I", len(counts)) + counts)

    def finish(self) -> None:
        """Write the last chunk, the summary (with its offsets) and the footer."""
        self._write_chunk()
        self._write(_record(DATA_END, struct.pack("<I", 0)))  # data section checksum: not computed
        summary_start = self._stream.tell()
        groups = [(SCHEMA, list(self._schemas.values())), (CHANNEL, list(self._channels.values())),
                  (STATISTICS, [self._statistics()]), (METADATA_INDEX, self._metadata_indexes),
                  (CHUNK_INDEX, self._chunk_indexes)]
        summary = bytearray()
        offsets = bytearray()
        for opcode, records in groups:
            if records:
                group = b"".join(records)
                group_start = summary_start + len(summary)
                offsets += _record(SUMMARY_OFFSET, struct.pack("<BQQ", opcode, group_start, len(group)))
                summary += group
        summary_offset_start = summary_start + len(summary)
        footer_fields = struct.pack("<BQQQ", FOOTER, 8 + 8 + 4, summary_start, summary_offset_start)
        crc = zlib.crc32(footer_fields, zlib.crc32(offsets, zlib.crc32(summary)))
        self._write(bytes(summary) + bytes(offsets) + footer_fields + struct.pack("<I", crc) + MAGIC)
        self._stream.flush()
