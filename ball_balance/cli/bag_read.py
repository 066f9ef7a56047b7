"""Reading the MCAP files of a bag for `bag info` and `bag play`, every record checked against
the file: a damaged file is one line naming it, the byte where the damage was found and what
was wrong (BagDamaged), never a play that stops early as if the bag had ended.

The `mcap` package's reader trusts the file: a damaged record length makes it read one message
as the rest of its chunk and end the iteration quietly (a play of 21 of 79 messages with exit
code 0), and other damage comes out of it as KeyError, OverflowError, OSError or
UnicodeDecodeError. Here it parses only the summary, and only once the footer has been
checked and the summary's checksum (when one was written) verified. The data section is read
by this module:
- every chunk is read whole and walked record by record: a record must fit in its chunk, a
  message must name a channel of the summary and lie in its chunk's time range, and where the
  chunk has message indexes, the messages found must be the ones they list (channel, time and
  place); its checksum is verified when one was written, its compression (zstd, lz4) undone;
- `check()` (`bag info`) walks the whole data section from the header to the summary: every
  chunk the summary indexes must be found, its schemas and channels must be the summary's,
  and it must match its checksum where one was written; a file without chunk indexes is
  played by such a walk too (in the file's order);
- the messages found must be as many as the summary's statistics count (`check()`, and a play
  from the start that read every message of its topics).
Not seen without checksums (`bag record` writes none for chunks, as rosbag2 by default): a
changed byte inside a message's data, publish time or sequence number.
"""
from __future__ import annotations

import contextlib
import errno
import heapq
import io
import os
import struct
import zlib
from typing import Dict, Iterator, List, Optional, Set, Tuple

from ball_balance.cli.errors import CliError
from ball_balance.cli.mcap_write import (
    CHANNEL,
    CHUNK,
    DATA_END,
    FOOTER,
    HEADER,
    MAGIC,
    MESSAGE,
    MESSAGE_INDEX,
    METADATA,
    SCHEMA,
)

_RECORD_HEAD = struct.Struct("<BQ")              # opcode, length of the record's body
_FOOTER = struct.Struct("<BQQQI")                # opcode, length (20), summary start, summary offsets start, crc
_CHUNK_FIELDS = struct.Struct("<QQQII")          # start, end, uncompressed size, crc, compression's length
_MESSAGE_FIELDS = struct.Struct("<HIQQ")         # channel, sequence, log time, publish time
_INDEX_FIELDS = struct.Struct("<HI")             # message index: channel, length of its entries
_INDEX_ENTRY = struct.Struct("<QQ")              # log time, offset in the chunk's records
# what the mcap package raises, or lets through, when it parses bytes that are not what they should be
_PARSE_ERRORS = (ValueError, struct.error, EOFError, KeyError, IndexError, OverflowError, MemoryError)


class BagDamaged(CliError):
    """A file of the bag is damaged: its path, the byte where that was found, what was wrong."""

    def __init__(self, path: str, offset: Optional[int], what: str):
        where = f" at byte {offset}" if offset is not None else ""
        super().__init__(f"{path}: damaged{where} ({what})")


@contextlib.contextmanager
def _parsing(path: str, offset: Optional[int], what: str):
    """The mcap package's errors while it parses a part of the file, as BagDamaged."""
    from mcap.exceptions import McapError

    try:
        yield
    except BagDamaged:
        raise
    except (McapError, *_PARSE_ERRORS) as error:
        raise BagDamaged(path, offset, f"{what}: {str(error) or type(error).__name__}") from None
    except OSError as error:
        if error.errno != errno.EINVAL:  # a seek to a negative offset read from the file
            raise
        raise BagDamaged(path, offset, f"{what}: it points outside the file") from None


class _Message:
    __slots__ = ("channel_id", "log_ns", "data")

    def __init__(self, channel_id: int, log_ns: int, data: bytes):
        self.channel_id, self.log_ns, self.data = channel_id, log_ns, data


class BagFile:
    """One MCAP file of a bag, open for reading: `summary`, `check()`, `messages()`.

    Opening it checks its magic bytes and footer and reads its summary (CliError when the file
    is not MCAP, was cut short or has no summary; BagDamaged when either is damaged)."""

    def __init__(self, path: str):
        self.path = path
        try:
            self._stream = open(path, "rb")
        except OSError as error:
            raise CliError(f"cannot read '{path}': {error.strerror}") from None
        try:
            self.size = os.fstat(self._stream.fileno()).st_size
            _check_magic(path, self._stream)
            self.data_end = self._footer()  # the summary's start: the data section ends there
            self.summary = self._summary()
            self._chunk_indexes = {chunk.chunk_start_offset: chunk for chunk in self.summary.chunk_indexes}
        except BaseException:
            self._stream.close()
            raise

    def __enter__(self) -> BagFile:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stream.close()

    @property
    def message_counts(self) -> Dict[int, int]:
        """Messages per channel id, as the summary's statistics count them ({} without statistics)."""
        statistics = self.summary.statistics
        return dict(statistics.channel_message_counts) if statistics is not None else {}

    # ---- footer and summary ------------------------------------------------------------------
    def _read_at(self, offset: int, size_bytes: int) -> bytes:
        self._stream.seek(offset)
        return self._stream.read(size_bytes)

    def _footer(self) -> int:
        """The summary's start, from a footer that fits the file (its checksum verified)."""
        footer_at = self.size - len(MAGIC) - _FOOTER.size
        if footer_at < 2 * len(MAGIC):
            raise BagDamaged(self.path, None, "too short to hold a header and a footer")
        opcode, length, summary_start, offsets_start, crc = _FOOTER.unpack(self._read_at(footer_at, _FOOTER.size))
        if opcode != FOOTER or length != _FOOTER.size - _RECORD_HEAD.size:
            raise BagDamaged(self.path, footer_at, "no footer record before the closing magic bytes")
        if summary_start == 0:
            raise CliError(f"'{self.path}' has no summary section (recording interrupted?)")
        if not len(MAGIC) < summary_start <= footer_at or not (
                offsets_start == 0 or summary_start <= offsets_start <= footer_at):
            raise BagDamaged(self.path, footer_at, "the footer places the summary outside the file")
        if crc:
            covered = self._read_at(summary_start, footer_at + _FOOTER.size - 4 - summary_start)
            if zlib.crc32(covered) != crc:
                raise BagDamaged(self.path, summary_start, "the summary does not match its checksum")
        return summary_start

    def _summary(self):
        from mcap.reader import SeekingReader

        with _parsing(self.path, self.data_end, "the summary cannot be read"):
            self._stream.seek(0)
            summary = SeekingReader(self._stream, record_size_limit=self.size).get_summary()
        if summary is None:
            raise CliError(f"'{self.path}' has no summary section (recording interrupted?)")
        for channel in summary.channels.values():
            if channel.schema_id and channel.schema_id not in summary.schemas:
                raise BagDamaged(self.path, self.data_end, f"the summary's channel {channel.id} names schema "
                                 f"{channel.schema_id}, which the file does not hold")
        counted = set(summary.statistics.channel_message_counts) if summary.statistics is not None else set()
        for chunk in summary.chunk_indexes:
            counted |= set(chunk.message_index_offsets)
            if not len(MAGIC) <= chunk.chunk_start_offset < chunk.chunk_start_offset + chunk.chunk_length \
                    <= self.data_end:
                raise BagDamaged(self.path, self.data_end, f"the summary places a chunk at byte "
                                 f"{chunk.chunk_start_offset}, outside the data section")
        unknown = sorted(counted - set(summary.channels))
        if unknown:
            raise BagDamaged(self.path, self.data_end, f"the summary counts messages of channel {unknown[0]}, "
                             "which it does not hold")
        return summary

    # ---- records -------------------------------------------------------------------------------
    def _record_head(self, offset: int, end: int) -> Tuple[int, int]:
        """(opcode, end offset) of the record at offset, which must end by `end`."""
        head = self._read_at(offset, _RECORD_HEAD.size)
        if offset + _RECORD_HEAD.size > end or len(head) < _RECORD_HEAD.size:
            raise BagDamaged(self.path, offset, "a record's head runs past the end of the data section")
        opcode, length = _RECORD_HEAD.unpack(head)
        record_end = offset + _RECORD_HEAD.size + length
        if record_end > end:
            past = "the file" if record_end > self.size else "the data section"
            raise BagDamaged(self.path, offset, f"a record's length runs past the end of {past}")
        return opcode, record_end

    def _chunk(self, offset: int, length: Optional[int], keep_data: bool) -> Tuple[List[tuple], list, int]:
        """The chunk record at offset, checked: ([(channel, log time, place)] of its messages in
        record order, [_Message] (their data only with keep_data), the offset after it)."""
        opcode, end = self._record_head(offset, self.data_end)
        if opcode != CHUNK or (length is not None and end - offset != length):
            raise BagDamaged(self.path, offset, "no chunk where the summary's chunk index says one starts")
        body = self._read_at(offset + _RECORD_HEAD.size, end - offset - _RECORD_HEAD.size)
        fields_end = _CHUNK_FIELDS.size
        if len(body) < fields_end + 8:
            raise BagDamaged(self.path, offset, "a chunk too short for its fields")
        start_ns, end_ns, uncompressed_bytes, crc, name_bytes = _CHUNK_FIELDS.unpack_from(body)
        records_at = fields_end + name_bytes + 8
        if records_at > len(body):
            raise BagDamaged(self.path, offset, "a chunk's compression name runs past its end")
        (records_bytes,) = struct.unpack_from("<Q", body, records_at - 8)
        if records_at + records_bytes != len(body):
            raise BagDamaged(self.path, offset, f"a chunk's records are {records_bytes} bytes, its length leaves "
                             f"{len(body) - records_at} for them")
        compression = bytes(body[fields_end:records_at - 8])
        records = memoryview(body)[records_at:records_at + records_bytes]
        if compression:
            records = self._decompress(offset, compression, records, uncompressed_bytes)
        if len(records) != uncompressed_bytes:
            raise BagDamaged(self.path, offset, f"a chunk's records are {len(records)} bytes, its header says "
                             f"{uncompressed_bytes}")
        if crc and zlib.crc32(records) != crc:
            raise BagDamaged(self.path, offset, "a chunk's records do not match its checksum")
        first_byte = offset + _RECORD_HEAD.size + records_at

        def damaged(place: int, what: str) -> BagDamaged:  # a file offset where the records are stored as they are
            if compression:
                return BagDamaged(self.path, offset, f"{what}, at byte {place} of the chunk's "
                                  f"{compression.decode(errors='replace')} records")
            return BagDamaged(self.path, first_byte + place, what)

        found, messages, place = [], [], 0
        while place < len(records):
            if place + _RECORD_HEAD.size > len(records):
                raise damaged(place, "a record's head runs past the end of its chunk")
            opcode, length = _RECORD_HEAD.unpack_from(records, place)
            record_end = place + _RECORD_HEAD.size + length
            if record_end > len(records):
                raise damaged(place, "a record's length runs past the end of its chunk")
            if opcode == MESSAGE:
                if length < _MESSAGE_FIELDS.size:
                    raise damaged(place, "a message record too short for its fields")
                channel_id, _, log_ns, _ = _MESSAGE_FIELDS.unpack_from(records, place + _RECORD_HEAD.size)
                if channel_id not in self.summary.channels:
                    raise damaged(place, f"a message of channel {channel_id}, which the file does not hold")
                if not start_ns <= log_ns <= end_ns:
                    raise damaged(place, "a message's log time lies outside its chunk's time range")
                found.append((channel_id, log_ns, place))
                data = bytes(records[place + _RECORD_HEAD.size + _MESSAGE_FIELDS.size:record_end]) if keep_data \
                    else None
                messages.append(_Message(channel_id, log_ns, data))
            elif opcode not in (SCHEMA, CHANNEL):
                raise damaged(place, f"a record of opcode 0x{opcode:02x}, which a chunk cannot hold")
            place = record_end
        return found, messages, end

    def _decompress(self, offset: int, compression: bytes, records, uncompressed_bytes: int):
        name = compression.decode(errors="replace")
        try:
            if name == "zstd":
                import zstandard

                return zstandard.ZstdDecompressor().decompress(records, max_output_size=uncompressed_bytes)
            if name == "lz4":
                import lz4.frame

                return lz4.frame.decompress(records)
        except ImportError as error:
            raise CliError(f"cannot read '{self.path}': its chunks are {name}-compressed and the Python package "
                           f"'{error.name}' is not installed") from None
        except Exception as error:  # noqa: BLE001 - zstd and lz4 errors have no common type
            raise BagDamaged(self.path, offset, f"a {name} chunk cannot be decompressed: {error}") from None
        raise BagDamaged(self.path, offset, f"a chunk names an unknown compression '{name}'")

    def _message_indexes(self, offset: int, end: int, only_these: bool) -> Tuple[Set[tuple], Dict[int, int], int]:
        """The message index records from offset on, up to `end` or (unless only_these: nothing
        else may come before `end`) the first other record: {(channel, log time, place)} they
        list, {channel: offset of its index}, the offset after them."""
        listed: Set[Tuple[int, int, int]] = set()
        places: Dict[int, int] = {}
        while offset < end:
            opcode, record_end = self._record_head(offset, end)
            if opcode != MESSAGE_INDEX:
                if only_these:
                    raise BagDamaged(self.path, offset, "no message index where the summary's chunk index says "
                                     "the chunk's message indexes are")
                break
            body = self._read_at(offset + _RECORD_HEAD.size, record_end - offset - _RECORD_HEAD.size)
            if len(body) < _INDEX_FIELDS.size:
                raise BagDamaged(self.path, offset, "a message index too short for its fields")
            channel_id, entries_bytes = _INDEX_FIELDS.unpack_from(body)
            if _INDEX_FIELDS.size + entries_bytes > len(body) or entries_bytes % _INDEX_ENTRY.size:
                raise BagDamaged(self.path, offset, "a message index's entries do not fit it")
            for log_ns, place in _INDEX_ENTRY.iter_unpack(body[_INDEX_FIELDS.size:_INDEX_FIELDS.size + entries_bytes]):
                listed.add((channel_id, log_ns, place))
            places[channel_id] = offset
            offset = record_end
        return listed, places, offset

    def _checked_chunk(self, offset: int, keep_data: bool = True) -> Tuple[list, int]:
        """The chunk at offset and its message indexes, checked against each other and against
        the summary's chunk index of it (if any): ([_Message], the offset after the indexes)."""
        index = self._chunk_indexes.get(offset)
        found, messages, end = self._chunk(offset, index.chunk_length if index else None, keep_data)
        if index is not None and index.message_index_length:
            index_end = end + index.message_index_length
            if index_end > self.data_end:
                raise BagDamaged(self.path, end, "the summary places a chunk's message indexes past the end of "
                                 "the data section")
            listed, places, after = self._message_indexes(end, index_end, only_these=True)
            if places != index.message_index_offsets:
                raise BagDamaged(self.path, end, "a chunk's message indexes are not where the summary's chunk "
                                 "index places them")
        else:
            listed, _, after = self._message_indexes(end, self.data_end, only_these=False)
        if listed and listed != set(found):
            raise BagDamaged(self.path, offset, f"a chunk's messages do not match its message indexes "
                             f"({len(found)} found, {len(listed)} listed)")
        return messages, after

    # ---- whole file --------------------------------------------------------------------------
    def _walk(self, keep_data: bool = True) -> Iterator[Tuple[int, int, object]]:
        """(opcode, offset, what) of every record of the data section, checked; what: a chunk's
        [_Message], a message (file without chunks), a metadata record's body, else None.
        Messages carry their data only with keep_data."""
        offset = len(MAGIC)
        while offset < self.data_end:
            opcode, end = self._record_head(offset, self.data_end)
            if opcode == CHUNK:
                messages, end = self._checked_chunk(offset, keep_data)
                yield opcode, offset, messages
            elif opcode == MESSAGE:
                body = self._read_at(offset + _RECORD_HEAD.size, end - offset - _RECORD_HEAD.size)
                if len(body) < _MESSAGE_FIELDS.size:
                    raise BagDamaged(self.path, offset, "a message record too short for its fields")
                channel_id, _, log_ns, _ = _MESSAGE_FIELDS.unpack_from(body)
                if channel_id not in self.summary.channels:
                    raise BagDamaged(self.path, offset, f"a message of channel {channel_id}, which the file "
                                     "does not hold")
                yield opcode, offset, _Message(channel_id, log_ns, body[_MESSAGE_FIELDS.size:] if keep_data else None)
            elif opcode in (METADATA, SCHEMA, CHANNEL, DATA_END):
                yield opcode, offset, self._read_at(offset + _RECORD_HEAD.size, end - offset - _RECORD_HEAD.size)
            elif opcode == HEADER and offset != len(MAGIC):
                raise BagDamaged(self.path, offset, "a second header record")
            if opcode == DATA_END:
                return
            offset = end

    def check(self) -> list:
        """Walk the whole data section (BagDamaged at the first damage): its messages must be
        the ones the summary counts, its chunks the ones the summary indexes, its schemas and
        channels the summary's, and where a checksum of it was written, its bytes must match
        that. Returns the file's metadata records (mcap's Metadata)."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Metadata, Schema

        counts: Dict[int, int] = {}
        chunks, metadata = set(), []
        for opcode, offset, found in self._walk(keep_data=False):
            if opcode == CHUNK:
                chunks.add(offset)
            elif opcode in (METADATA, SCHEMA, CHANNEL):
                kind, record_type, summary_records = {
                    METADATA: ("metadata record", Metadata, None), SCHEMA: ("schema", Schema, self.summary.schemas),
                    CHANNEL: ("channel", Channel, self.summary.channels)}[opcode]
                with _parsing(self.path, offset, f"a {kind} cannot be read"):
                    record = record_type.read(ReadDataStream(io.BytesIO(found)))
                if summary_records is None:
                    metadata.append(record)
                elif summary_records.get(record.id) != record:
                    raise BagDamaged(self.path, offset, f"{kind} {record.id} differs from the summary's")
            elif opcode == DATA_END:
                self._check_data_crc(offset, found)
            for message in found if opcode == CHUNK else [found] if opcode == MESSAGE else []:
                counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
        missing = sorted({c.chunk_start_offset for c in self.summary.chunk_indexes} - chunks)
        if missing:
            raise BagDamaged(self.path, missing[0], "no chunk where the summary's chunk index says one starts")
        self._check_counts(counts, set(self.summary.channels))
        return metadata

    def _check_data_crc(self, data_end_at: int, body: bytes) -> None:
        """The data section (up to its DataEnd record at data_end_at) against the checksum there."""
        (crc,) = struct.unpack_from("<I", body) if len(body) >= 4 else (0,)
        if not crc:
            return
        self._stream.seek(0)
        computed, left = 0, data_end_at
        while left > 0:
            block = self._stream.read(min(left, 1 << 20))
            computed, left = zlib.crc32(block, computed), left - len(block)
        if computed != crc:
            raise BagDamaged(self.path, None, "the data section does not match its checksum")

    def _check_counts(self, counts: Dict[int, int], channel_ids: Set[int]) -> None:
        """The messages found of these channels against the statistics' count."""
        expected = {c: n for c, n in self.message_counts.items() if c in channel_ids and n}
        found = {c: n for c, n in counts.items() if n}
        if self.summary.statistics is not None and found != expected:
            raise BagDamaged(self.path, None, f"the summary counts {sum(expected.values())} messages"
                             f"{' of the topics played' if channel_ids != set(self.summary.channels) else ''}, "
                             f"the file holds {sum(found.values())}")

    def messages(self, channel_ids: Set[int], first_ns: Optional[int] = None) -> Iterator[Tuple[int, int, bytes]]:
        """(channel id, log time, data) of the file's messages of these channels from log time
        first_ns (None: all), in log time order (a file without chunk indexes: in the file's
        order), each chunk checked as it is read. Having read them all, their number is checked
        against the summary's count."""
        counts: Dict[int, int] = {}
        for message in self._messages_in_order(channel_ids, first_ns):
            counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
            if first_ns is None or message.log_ns >= first_ns:
                yield message.channel_id, message.log_ns, message.data
        if first_ns is None:
            self._check_counts(counts, channel_ids)

    def _messages_in_order(self, channel_ids: Set[int], first_ns: Optional[int]) -> Iterator[_Message]:
        if not self.summary.chunk_indexes:
            for opcode, _, found in self._walk():
                for message in found if opcode == CHUNK else [found] if opcode == MESSAGE else []:
                    if message.channel_id in channel_ids:
                        yield message
            return
        # a heap of chunks (keyed by their first log time) and of the messages of the chunks
        # read so far: a chunk is read once the messages before its first log time are out
        queue: list = []
        for chunk in self.summary.chunk_indexes:
            if first_ns is not None and chunk.message_end_time < first_ns:
                continue
            if chunk.message_index_offsets and not channel_ids & set(chunk.message_index_offsets):
                continue
            queue.append((chunk.message_start_time, 0, chunk.chunk_start_offset, 0, chunk))
        heapq.heapify(queue)
        while queue:
            log_ns, kind, chunk_offset, number, item = heapq.heappop(queue)
            if kind == 1:
                yield item
                continue
            messages, _ = self._checked_chunk(chunk_offset)
            for number, message in enumerate(messages):
                if message.channel_id in channel_ids:
                    heapq.heappush(queue, (message.log_ns, 1, chunk_offset, number, message))


def _check_magic(path: str, stream) -> None:
    """An MCAP file starts and ends with the magic bytes; one that only starts with them was cut
    short (the recorder was killed, or the disk filled) and has no summary to read."""
    if stream.read(len(MAGIC)) != MAGIC:
        raise CliError(f"'{path}' is not an MCAP file (it does not start with the MCAP magic bytes)")
    size_bytes = stream.seek(0, os.SEEK_END)
    stream.seek(max(0, size_bytes - len(MAGIC)))
    if size_bytes < 2 * len(MAGIC) or stream.read() != MAGIC:
        raise CliError(f"'{path}' ends before its footer: the recording was cut short (killed, or the "
                       "disk filled) and the file has no summary or index (the MCAP tool's `mcap recover` "
                       "rebuilds them)")
    stream.seek(0)
