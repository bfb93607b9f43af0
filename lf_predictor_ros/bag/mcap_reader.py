"""MCAP bag reader for rosbag2-style bags. ROS-free: yields serialized CDR bytes.

`BagReader(path)` accepts an `.mcap` file or a rosbag2 directory (`metadata.yaml` plus one
`.mcap` file). It scans the data section record by record (reading chunk headers only), so it
reads finished files, files written without chunking (rosbag2's `fastwrite`), and files whose
writer was killed: such a file has no summary and ends in a partial record; every record before
the first incomplete or corrupt one is used, and `recover(src, dst)` rewrites them as a finished
file. Messages come out in log-time order (ties in file order) by merging chunks on their
start times, so memory holds only chunks that overlap in time.

A file that is not MCAP, is not a `ros2` profile bag, or is corrupt inside a finished file
raises `BagError` (a ValueError) with a message saying what is wrong.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
import heapq
from io import BytesIO
import os
from pathlib import Path
import struct
from types import TracebackType
from typing import IO, Any, NamedTuple
import zlib

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema, Statistics
from mcap.stream_reader import breakup_chunk
import yaml

from lf_predictor_ros.bag.mcap_writer import (
    METADATA_KEY,
    METADATA_NAME,
    PROFILE,
    BagError,
    BagWriter,
)

__all__ = ['BagError', 'BagMessage', 'BagReader', 'TopicInfo', 'recover']

MAGIC = b'\x89MCAP0\r\n'
_RECORD_PREFIX = struct.Struct('<BQ')  # opcode, content length
_CHUNK_TIMES = struct.Struct('<QQQI')  # start, end, uncompressed size, uncompressed crc
_FOOTER_LENGTH = 20  # [bytes] summary start u64 + summary offset start u64 + crc u32
_FOOTER_RECORD = 1 + 8 + _FOOTER_LENGTH


class BagMessage(NamedTuple):
    """One message: topic, type name, log time [ns] and its serialized CDR bytes."""

    topic: str
    type_name: str
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicInfo:
    """What the bag says about one topic."""

    topic: str
    type_name: str
    message_encoding: str
    schema_encoding: str
    definition: str
    offered_qos_profiles: str
    type_hash: str
    message_count: int


@dataclass
class _Segment:
    """A chunk, or a run of top-level messages, located by file offsets."""

    start_ns: int
    end_ns: int
    order: int
    chunk_offset: int = -1  # offset of the chunk record's content; -1 for top-level messages
    chunk_length: int = 0
    message_offsets: list[tuple[int, int]] = field(default_factory=list)  # (offset, length)


@dataclass
class _Index:
    """Everything the scan learns about the file."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    segments: list[_Segment] = field(default_factory=list)
    counts: dict[int, int] = field(default_factory=dict)
    statistics: Statistics | None = None
    complete: bool = False
    problem: str | None = None


def resolve_bag_path(path: str | os.PathLike[str]) -> Path:
    """The `.mcap` file of a bag given as a file or as a rosbag2 directory."""
    bag = Path(path)
    if not bag.exists():
        raise BagError(f'bag {str(bag)!r} does not exist; give an .mcap file or a rosbag2 '
                       'directory')
    if bag.is_file():
        return bag
    meta_path = bag / 'metadata.yaml'
    if not meta_path.is_file():
        raise BagError(f'{str(bag)!r} is a directory without metadata.yaml, so not a rosbag2 '
                       'bag; give the .mcap file itself')
    try:
        info = yaml.safe_load(meta_path.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
        storage = info.get('storage_identifier', 'mcap')
        files = [str(name) for name in info.get('relative_file_paths') or []]
    except (yaml.YAMLError, KeyError, TypeError, AttributeError) as err:
        raise BagError(f'{str(meta_path)!r} is not rosbag2 metadata ({err}); repair or remove '
                       'it and open the .mcap file directly') from None
    if storage != 'mcap':
        raise BagError(f'bag {str(bag)!r} uses storage {storage!r}; only MCAP is supported '
                       '(convert with `ros2 bag convert` or rosbags-convert)')
    if not files:
        files = sorted(p.name for p in bag.glob('*.mcap'))
    if len(files) != 1:
        raise BagError(f'bag {str(bag)!r} has {len(files)} data files ({files}); only '
                       'single-file bags are supported: merge them with `ros2 bag convert`')
    data_file = bag / Path(files[0]).name
    if not data_file.is_file():
        raise BagError(f'bag {str(bag)!r} lists {files[0]!r} in metadata.yaml but the file is '
                       'missing')
    return data_file


class BagReader:
    """Read an MCAP bag (file or rosbag2 directory); use as a context manager.

    `allow_incomplete=True` (default) reads a file without a summary (a killed writer) up to the
    first incomplete or corrupt record and reports it in `complete` / `problem`;
    `allow_incomplete=False` raises BagError for such a file.
    """

    def __init__(self, path: str | os.PathLike[str], *, allow_incomplete: bool = True) -> None:
        self.path = resolve_bag_path(path)
        try:
            self._file: IO[bytes] = open(self.path, 'rb')  # noqa: SIM115
        except OSError as err:
            raise BagError(f'cannot read bag {str(self.path)!r}: {err.strerror or err}') from None
        try:
            self._size = os.fstat(self._file.fileno()).st_size
            self._index = _scan(self._file, self._size, str(self.path))
            if not self._index.complete and not allow_incomplete:
                raise BagError(f'bag {str(self.path)!r} is incomplete ({self._index.problem}); '
                               'the writer was probably killed: run recover() on it or open it '
                               'with allow_incomplete=True')
            if (not self._index.complete or self._index.statistics is None
                    or not self._index.channels):
                self._validate_chunks()
        except BaseException:
            self._file.close()
            raise

    # -- context manager ------------------------------------------------------------------
    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Close the file (idempotent)."""
        self._file.close()

    # -- what is in the bag ---------------------------------------------------------------
    @property
    def complete(self) -> bool:
        """True for a finished file (data end, summary and footer all valid)."""
        return self._index.complete

    @property
    def problem(self) -> str | None:
        """Why the file is incomplete, or None."""
        return self._index.problem

    def topics(self) -> dict[str, str]:
        """Topic name -> type name (`pkg/msg/Type`)."""
        return {info.topic: info.type_name for info in self.topic_infos().values()}

    def topic_infos(self) -> dict[str, TopicInfo]:
        """Topic name -> TopicInfo (schema text, QoS, message count)."""
        infos: dict[str, TopicInfo] = {}
        for channel_id, channel in sorted(self._index.channels.items()):
            schema = self._index.schemas.get(channel.schema_id)
            infos[channel.topic] = TopicInfo(
                topic=channel.topic,
                type_name=schema.name if schema else '',
                message_encoding=channel.message_encoding,
                schema_encoding=schema.encoding if schema else '',
                definition=schema.data.decode('utf-8', 'replace') if schema else '',
                offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''),
                type_hash=channel.metadata.get('topic_type_hash', ''),
                message_count=self._count(channel_id),
            )
        return infos

    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records by name (e.g. `rosbag2` -> {'serialized_metadata': yaml text})."""
        return {name: dict(values) for name, values in self._index.metadata.items()}

    def custom_data(self) -> dict[str, str]:
        """rosbag2 custom data of the bag metadata record (`BagWriter`'s ``custom_data``).

        Empty when the bag has none, has no `rosbag2` metadata record (e.g. a bag whose writer
        was killed) or the record's YAML holds no valid map: it is information, never required.
        """
        record = self._index.metadata.get(METADATA_NAME, {})
        try:
            values = yaml.safe_load(record.get(METADATA_KEY, '')) or {}
            custom = values.get('custom_data') or {}
        except (yaml.YAMLError, AttributeError):
            return {}
        if not isinstance(custom, dict):
            return {}
        return {str(key): str(value) for key, value in custom.items()}

    @property
    def message_count(self) -> int:
        """Number of readable messages."""
        return sum(self._count(channel_id) for channel_id in self._index.channels)

    @property
    def start_time_ns(self) -> int:
        """Earliest log time [ns] (0 for an empty bag)."""
        segments = self._index.segments
        return min((s.start_ns for s in segments), default=0)

    @property
    def end_time_ns(self) -> int:
        """Latest log time [ns] (0 for an empty bag)."""
        segments = self._index.segments
        return max((s.end_ns for s in segments), default=0)

    # -- messages -------------------------------------------------------------------------
    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages of `topics` (default all) in log-time order, ties in file order."""
        wanted = None if topics is None else set(topics)
        if wanted is not None and (unknown := wanted - set(self.topics())):
            raise BagError(f'topics {sorted(unknown)} are not in bag {str(self.path)!r}; it has '
                           f'{sorted(self.topics())}')
        for channel, message in self.records():
            if wanted is None or channel.topic in wanted:
                schema = self._index.schemas.get(channel.schema_id)
                yield BagMessage(channel.topic, schema.name if schema else '',
                                 message.log_time, message.data)

    def records(self) -> Iterator[tuple[Channel, Message]]:
        """Raw (channel, message) records in log-time order (publish time, sequence kept)."""
        segments = sorted(self._index.segments, key=lambda s: (s.start_ns, s.order))
        heap: list[tuple[int, int, int, Message]] = []
        next_segment = 0
        while next_segment < len(segments) or heap:
            # Load every segment that may hold a message not later than the heap's earliest.
            while next_segment < len(segments) and (
                    not heap or segments[next_segment].start_ns <= heap[0][0]):
                segment = segments[next_segment]
                for position, message in enumerate(self._segment_messages(segment)):
                    heapq.heappush(heap, (message.log_time, segment.order, position, message))
                next_segment += 1
            message = heapq.heappop(heap)[3]
            channel = self._index.channels.get(message.channel_id)
            if channel is None:
                raise BagError(f'bag {str(self.path)!r} has a message on channel '
                               f'{message.channel_id} that no channel record defines; the file '
                               'is corrupt')
            yield channel, message

    # -- internals ------------------------------------------------------------------------
    def _count(self, channel_id: int) -> int:
        if self._index.counts:
            return self._index.counts.get(channel_id, 0)
        stats = self._index.statistics
        return stats.channel_message_counts.get(channel_id, 0) if stats else 0

    def _segment_messages(self, segment: _Segment) -> list[Message]:
        try:
            return _decode_segment(self._file, segment, self._index)
        except BagError:
            raise
        except Exception as err:  # zstd/lz4/crc/struct errors of a damaged chunk
            raise BagError(f'bag {str(self.path)!r} is corrupt: chunk at byte '
                           f'{segment.chunk_offset} does not decode ({err}); run recover() to '
                           'save the readable part') from None

    def _validate_chunks(self) -> None:
        """Decode every segment once: learn channels, count messages, cut at the first bad one."""
        index = self._index
        counts: dict[int, int] = {}
        for kept, segment in enumerate(index.segments):
            try:
                messages = _decode_segment(self._file, segment, index)
            except Exception as err:  # a damaged chunk ends the readable part
                if index.complete:
                    raise BagError(f'bag {str(self.path)!r} is corrupt: chunk at byte '
                                   f'{segment.chunk_offset} does not decode ({err})') from None
                index.problem = (f'chunk at byte {segment.chunk_offset} does not decode '
                                 f'({err})')
                del index.segments[kept:]
                break
            for message in messages:
                counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
        index.counts = counts


def _decode_segment(file: IO[bytes], segment: _Segment, index: _Index) -> list[Message]:
    """Messages of one segment; schemas and channels found on the way go into `index`."""
    if segment.chunk_offset < 0:
        messages = []
        for offset, length in segment.message_offsets:
            file.seek(offset)
            messages.append(Message.read(ReadDataStream(BytesIO(file.read(length))), length))
        return messages
    file.seek(segment.chunk_offset)
    content = file.read(segment.chunk_length)
    chunk = Chunk.read(ReadDataStream(BytesIO(content)))
    messages = []
    for record in breakup_chunk(chunk, validate_crc=True):
        if isinstance(record, Message):
            messages.append(record)
        elif isinstance(record, Schema):
            index.schemas.setdefault(record.id, record)
        elif isinstance(record, Channel):
            index.channels.setdefault(record.id, record)
    return messages


def _read_exact(file: IO[bytes], size: int) -> bytes:
    data = file.read(size)
    if len(data) != size:
        raise EOFError
    return data


def _scan(file: IO[bytes], size: int, name: str) -> _Index:
    """Walk the data section; then read the summary if the file is finished."""
    index = _Index()
    head = file.read(len(MAGIC))
    if head != MAGIC:
        what = 'is empty' if not head else 'does not start with the MCAP magic bytes'
        raise BagError(f'{name!r} is not an MCAP bag: the file {what}')
    prefix = file.read(_RECORD_PREFIX.size)
    if len(prefix) < _RECORD_PREFIX.size or prefix[0] != Opcode.HEADER:
        raise BagError(f'{name!r} is not a valid MCAP bag: no header record after the magic '
                       '(file truncated or damaged at the start)')
    length = _RECORD_PREFIX.unpack(prefix)[1]
    if len(MAGIC) + _RECORD_PREFIX.size + length > size:
        raise BagError(f'{name!r} is truncated inside its header record')
    try:
        profile = ReadDataStream(BytesIO(file.read(length))).read_prefixed_string()
    except (McapError, UnicodeDecodeError, struct.error):
        raise BagError(f'{name!r} is not a valid MCAP bag: its header record is damaged') from None
    if profile != PROFILE:
        raise BagError(f'{name!r} is an MCAP file with profile {profile!r}, not a ROS 2 bag '
                       f'(profile {PROFILE!r})')
    data_end = _scan_data_section(file, size, index)
    if data_end is None:
        return index
    _read_summary(file, size, data_end, index)
    return index


def _scan_data_section(file: IO[bytes], size: int, index: _Index) -> int | None:
    """Index the data section; return where it ends, or None if it ends in damage."""
    position = file.tell()
    order = 0
    while True:
        if position + _RECORD_PREFIX.size > size:
            index.problem = f'file ends at byte {size} without a data end record'
            return None
        file.seek(position)
        opcode: int
        length: int
        opcode, length = _RECORD_PREFIX.unpack(file.read(_RECORD_PREFIX.size))
        content_at = position + _RECORD_PREFIX.size
        if opcode == 0 or content_at + length > size:
            index.problem = (f'record at byte {position} is incomplete or damaged '
                             f'(opcode {opcode}, length {length}, file size {size})')
            return None
        if opcode == Opcode.DATA_END:
            return content_at + length
        try:
            order = _index_record(file, opcode, content_at, length, order, index)
        except (EOFError, struct.error, UnicodeDecodeError, ValueError) as err:
            index.problem = f'record at byte {position} (opcode {opcode}) is damaged ({err})'
            return None
        position = content_at + length


def _index_record(file: IO[bytes], opcode: int, content_at: int, length: int, order: int,
                  index: _Index) -> int:
    """Add one data-section record to the index; return the next segment order number."""
    if opcode == Opcode.CHUNK:
        start, end, _size, _crc = _CHUNK_TIMES.unpack(_read_exact(file, _CHUNK_TIMES.size))
        compression_length = struct.unpack('<I', _read_exact(file, 4))[0]
        _read_exact(file, compression_length)
        records_length = struct.unpack('<Q', _read_exact(file, 8))[0]
        if _CHUNK_TIMES.size + 4 + compression_length + 8 + records_length != length:
            raise ValueError('chunk lengths do not add up')
        index.segments.append(_Segment(start, end, order, content_at, length))
        return order + 1
    if opcode == Opcode.MESSAGE:
        message = Message.read(ReadDataStream(BytesIO(_read_exact(file, length))), length)
        last = index.segments[-1] if index.segments else None
        if last is not None and last.chunk_offset < 0 and last.order == order - 1:
            last.message_offsets.append((content_at, length))
            last.start_ns = min(last.start_ns, message.log_time)
            last.end_ns = max(last.end_ns, message.log_time)
            return order
        index.segments.append(_Segment(message.log_time, message.log_time, order,
                                       message_offsets=[(content_at, length)]))
        return order + 1
    if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA):
        _add_definition(ReadDataStream(BytesIO(_read_exact(file, length))), opcode, index)
    return order


def _add_definition(stream: ReadDataStream, opcode: int, index: _Index) -> None:
    """Schema, channel or metadata record into the index."""
    if opcode == Opcode.SCHEMA:
        schema = Schema.read(stream)
        index.schemas.setdefault(schema.id, schema)
    elif opcode == Opcode.CHANNEL:
        channel = Channel.read(stream)
        index.channels.setdefault(channel.id, channel)
    elif opcode == Opcode.METADATA:
        metadata = Metadata.read(stream)
        index.metadata[metadata.name] = dict(metadata.metadata)


def _read_summary(file: IO[bytes], size: int, data_end: int, index: _Index) -> None:
    """Check footer and summary CRC; take schemas, channels, statistics from the summary."""
    footer_at = size - len(MAGIC) - _FOOTER_RECORD
    if footer_at < data_end:
        index.problem = 'file ends after the data section without a footer'
        return
    file.seek(footer_at)
    footer = file.read(_FOOTER_RECORD + len(MAGIC))
    opcode, length = _RECORD_PREFIX.unpack_from(footer)
    if opcode != Opcode.FOOTER or length != _FOOTER_LENGTH or footer[-len(MAGIC):] != MAGIC:
        index.problem = 'footer or closing magic bytes are missing or damaged'
        return
    summary_start, _offsets_start, summary_crc = struct.unpack_from('<QQI', footer, 9)
    if summary_start == 0:
        index.complete = True
        return
    if not data_end <= summary_start <= footer_at:
        index.problem = f'footer points to a summary at byte {summary_start}, outside the file'
        return
    file.seek(summary_start)
    summary = file.read(footer_at - summary_start)
    if summary_crc and zlib.crc32(footer[:_FOOTER_RECORD - 4], zlib.crc32(summary)) != (
            summary_crc):
        index.problem = 'summary CRC mismatch: the summary is damaged'
        return
    _parse_summary(summary, index)
    index.complete = True


def _parse_summary(summary: bytes, index: _Index) -> None:
    position = 0
    while position + _RECORD_PREFIX.size <= len(summary):
        opcode, length = _RECORD_PREFIX.unpack_from(summary, position)
        content = summary[position + _RECORD_PREFIX.size:position + _RECORD_PREFIX.size + length]
        stream = ReadDataStream(BytesIO(content))
        if opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            _add_definition(stream, opcode, index)
        elif opcode == Opcode.STATISTICS:
            index.statistics = Statistics.read(stream)
        position += _RECORD_PREFIX.size + length


def recover(src: str | os.PathLike[str], dst: str | os.PathLike[str], *,
            overwrite: bool = False, **writer_options: Any) -> int:
    """Rewrite the readable part of bag `src` (e.g. from a killed recorder) as a finished `dst`.

    Keeps topics, schema texts, QoS metadata, log and publish times, and the custom data of a
    finished bag. Returns the number of messages written. `writer_options` go to BagWriter
    (chunk_size, compression, custom_data).
    """
    with BagReader(src, allow_incomplete=True) as reader:
        writer_options.setdefault('custom_data', reader.custom_data())
        return _rewrite(reader, src, BagWriter(dst, overwrite=overwrite, **writer_options))


def _rewrite(reader: BagReader, src: str | os.PathLike[str], writer: BagWriter) -> int:
    """Copy every readable message of ``reader`` with its topic to ``writer``, close it."""
    with writer:
        channel_ids: dict[int, int] = {}
        for channel_id, channel in sorted(reader._index.channels.items()):
            schema = reader._index.schemas.get(channel.schema_id)
            if schema is None:
                raise BagError(f'channel {channel.topic!r} of {str(src)!r} has no schema; '
                               'cannot rewrite it')
            channel_ids[channel_id] = writer.add_topic(
                channel.topic, schema.name, channel.metadata.get('offered_qos_profiles'),
                type_hash=channel.metadata.get('topic_type_hash', ''),
                definition=schema.data.decode('utf-8'))
        count = 0
        for channel, message in reader.records():
            writer.write(channel_ids[channel.id], message.log_time, message.data,
                         message.publish_time)
            count += 1
    return count
