"""MCAP bag writer following rosbag2's conventions. ROS-free: takes serialized CDR bytes.

What the file holds (what `rosbag2_storage_mcap` writes in Jazzy, so `ros2 bag`, Foxglove and
`rosbags` read it):
- header profile `ros2`;
- one schema per type: name `pkg/msg/Type`, encoding `ros2msg`, the full definition text
  (see `msgdefs.full_definition`);
- one channel per topic: message encoding `cdr`, metadata `offered_qos_profiles` (rosbag2 v9 YAML
  text, a list of QoS profiles) and `topic_type_hash` (RIHS01 hash, empty when unknown);
- messages in zstd (default), lz4 or uncompressed chunks, with message indexes;
- on `close()`: a metadata record `rosbag2` whose key `serialized_metadata` is the YAML of the
  bag metadata (the content of a rosbag2 `metadata.yaml` without its top-level key; its
  `custom_data` map holds the writer's `custom_data`, as `ros2 bag record --custom-data` does),
  then the summary (schemas, channels, statistics, chunk and metadata indexes) and the footer.

Crash bound: every finished chunk is handed to the operating system at once (the file is not
buffered in Python). A chunk is finished when it holds `chunk_size` bytes (default 256 KiB), when
its messages span `max_chunk_duration` seconds of log time (default 1 s), when `write()` is
called `max_chunk_duration` seconds of wall time after the chunk was started, and on `flush()`.
So a SIGKILL loses at most the open chunk: at most `chunk_size` bytes and, provided `flush()` is
called at least every `max_chunk_duration` seconds while the stream is idle (the recorder does),
at most `max_chunk_duration` seconds of recording. The truncated file has no summary;
`mcap_reader.BagReader` reads it and `mcap_reader.recover` rewrites it complete.

Write failure (disk full: ENOSPC, EDQUOT, or EFBIG from a file-size limit; or any other OSError
of the file): the writer stops for good. It cuts the file back to the end of the last complete
chunk (`ftruncate` needs no free space), so the file is like one from a killed writer: every
finished chunk is readable and `recover` rewrites them as a finished bag. The call that met the
error raises `BagWriteError` (path, bytes kept, errno); later `write()` calls raise it again,
`flush()` does nothing and `close()` only closes the file (a summary cannot be written). The
messages of the failed chunk are counted in `lost_count`.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import errno
import os
from pathlib import Path
import threading
import time
from types import TracebackType
from typing import Any

from mcap.exceptions import UnsupportedCompressionError
from mcap.writer import CompressionType, Writer
import yaml

from lf_predictor_ros.bag.msgdefs import full_definition

PROFILE = 'ros2'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'
METADATA_NAME = 'rosbag2'
METADATA_KEY = 'serialized_metadata'
ROSBAG2_VERSION = 9  # metadata format version of rosbag2 in Jazzy
ROS_DISTRO = 'jazzy'
LIBRARY = 'lf_predictor_ros'

DEFAULT_CHUNK_SIZE = 256 * 1024  # [bytes] uncompressed chunk size that closes a chunk
DEFAULT_MAX_CHUNK_DURATION = 1.0  # [s] longest log-time / wall-time span of one chunk
_MESSAGE_RECORD_OVERHEAD = 31  # [bytes] opcode 1 + length 8 + channel 2 + seq 4 + times 2 * 8
_NEVER = 2**62  # [bytes] chunk size handed to mcap: chunks are closed here, not there

# rmw's "infinite" duration (RMW_DURATION_INFINITE = INT64_MAX ns) as rosbag2 writes it.
INFINITE_DURATION_NS = 2**63 - 1  # [ns]

COMPRESSIONS = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                'none': CompressionType.NONE}


# errno values that mean "no room for the bytes": no space, quota, file-size limit (RLIMIT_FSIZE).
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


class BagError(ValueError):
    """A bag cannot be written or read: bad path, corrupt or foreign file, bad arguments."""


class BagWriteError(BagError):
    """Writing the bag file failed (disk full or an I/O error); the writer has stopped.

    `bytes_kept` is the file's length after the cut back to the last complete chunk;
    `errno` the operating system's error number; `disk_full` whether it means no room.
    """

    def __init__(self, message: str, *, path: Path, bytes_kept: int, errno_value: int | None
                 ) -> None:
        super().__init__(message)
        self.path = path
        self.bytes_kept = bytes_kept
        self.errno = errno_value
        self.disk_full = errno_value in DISK_FULL_ERRNOS


def rmw_time(nanoseconds: int) -> dict[str, int]:
    """A duration in rosbag2's YAML form `{sec, nsec}`."""
    return {'sec': nanoseconds // 1_000_000_000, 'nsec': nanoseconds % 1_000_000_000}


def qos_profile_dict(*, reliability: str = 'reliable', durability: str = 'volatile',
                     history: str = 'keep_last', depth: int = 10,
                     deadline_ns: int = INFINITE_DURATION_NS,
                     lifespan_ns: int = INFINITE_DURATION_NS, liveliness: str = 'automatic',
                     liveliness_lease_duration_ns: int = INFINITE_DURATION_NS,
                     avoid_ros_namespace_conventions: bool = False) -> dict[str, Any]:
    """One QoS profile as rosbag2 v9 serializes it (policy names as in rmw's `*_to_str`).

    The defaults are the publisher profile of the interface contract: reliable, volatile,
    keep_last 10.
    """
    return {
        'history': history,
        'depth': depth,
        'reliability': reliability,
        'durability': durability,
        'deadline': rmw_time(deadline_ns),
        'lifespan': rmw_time(lifespan_ns),
        'liveliness': liveliness,
        'liveliness_lease_duration': rmw_time(liveliness_lease_duration_ns),
        'avoid_ros_namespace_conventions': avoid_ros_namespace_conventions,
    }


def qos_profiles_yaml(profiles: Sequence[Mapping[str, Any]]) -> str:
    """The `offered_qos_profiles` channel metadata text for a list of QoS profile dicts."""
    text: str = yaml.safe_dump([dict(p) for p in profiles], sort_keys=False,
                               default_flow_style=False)
    return text


DEFAULT_QOS_YAML = qos_profiles_yaml([qos_profile_dict()])


@dataclass
class _TopicStats:
    """What the rosbag2 metadata needs per topic."""

    channel_id: int
    type_name: str
    qos_yaml: str
    type_hash: str
    message_count: int = 0


class _DirectStream:
    """Write-through file stream: each write reaches the OS at once (no Python buffer)."""

    def __init__(self, raw: Any) -> None:
        self._raw = raw
        self._position = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data)
        while view:
            written = self._raw.write(view)
            view = view[written:]
            self._position += written
        return len(data)

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        """Nothing buffered here; the OS has every byte already."""

    def truncate(self, size: int) -> None:
        """Cut the file to `size` bytes (frees space; works on a full disk)."""
        self._raw.truncate(size)
        self._position = size

    def close(self) -> None:
        self._raw.close()


def _open_for_writing(path: Path, overwrite: bool) -> Any:
    """Create parent folders and open `path` unbuffered, with a clear BagError on failure."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BagError(f'cannot write bag {str(path)!r}: cannot create its folder '
                       f'({err.strerror or err}); choose a writable output path') from None
    try:
        return open(path, 'wb' if overwrite else 'xb', buffering=0)  # noqa: SIM115
    except FileExistsError:
        raise BagError(f'bag {str(path)!r} exists already; choose another output path, '
                       'delete the file, or pass overwrite=True') from None
    except OSError as err:
        raise BagError(f'cannot write bag {str(path)!r}: {err.strerror or err}; choose a '
                       'writable output path') from None


class BagWriter:
    """Write an MCAP bag with rosbag2 conventions; use as a context manager.

    Thread-safe; `close()` is idempotent and may be called from a signal handler: if the signal
    interrupts a `write()` on the same thread, closing is deferred to the end of that write.
    ``custom_data``: rosbag2 custom data (str -> str) for the bag metadata, e.g. where a
    simulated recording came from (`sim_bag`); `BagReader.custom_data()` reads it back.
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 compression: str = 'zstd',
                 max_chunk_duration: float = DEFAULT_MAX_CHUNK_DURATION,
                 overwrite: bool = False,
                 custom_data: Mapping[str, str] | None = None) -> None:
        if chunk_size < 1:
            raise BagError(f'chunk_size must be >= 1 byte, got {chunk_size}; 262144 is a good '
                           'default')
        if not max_chunk_duration > 0.0:
            raise BagError(f'max_chunk_duration must be > 0 s, got {max_chunk_duration}')
        if compression not in COMPRESSIONS:
            raise BagError(f'compression must be one of {sorted(COMPRESSIONS)}, '
                           f'got {compression!r}')
        self._custom_data = _checked_custom_data(custom_data or {})
        self.path = Path(path)
        self.chunk_size = chunk_size
        self.compression = compression
        self.max_chunk_duration = max_chunk_duration
        self._max_chunk_ns = int(max_chunk_duration * 1e9)
        raw = _open_for_writing(self.path, overwrite)
        self._stream = _DirectStream(raw)
        try:
            self._mcap = Writer(self._stream, chunk_size=_NEVER,  # type: ignore[arg-type]
                                compression=COMPRESSIONS[compression])
        except UnsupportedCompressionError as err:
            raw.close()
            self.path.unlink(missing_ok=True)
            raise BagError(f'{err}; install the Python package for it or use '
                           "compression='none'") from None
        try:
            self._mcap.start(profile=PROFILE, library=LIBRARY)
        except OSError as err:
            raw.close()
            self.path.unlink(missing_ok=True)
            raise BagError(f'cannot write bag {str(self.path)!r}: {err.strerror or err}; '
                           'choose an output path with free space') from None
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _TopicStats] = {}
        self._by_channel: dict[int, _TopicStats] = {}
        self._lock = threading.Lock()
        self._owner: int | None = None
        self._close_requested = False
        self._closed = False
        self._start_ns: int | None = None
        self._end_ns = 0
        self._message_count = 0
        self._chunk_messages = 0
        self._lost_count = 0
        self._error: BagWriteError | None = None
        self._good_offset = self._stream.tell()  # [bytes] end of the last complete record
        self._chunk_bytes = 0
        self._chunk_first_log_ns = 0
        self._chunk_wall_start = 0.0

    # -- context manager ------------------------------------------------------------------
    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """True once the summary and footer are written."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages accepted by `write()` so far (see `lost_count` after a write failure)."""
        return self._message_count

    @property
    def lost_count(self) -> int:
        """Accepted messages that never reached the file (the chunk open at a write failure)."""
        return self._lost_count

    @property
    def bytes_written(self) -> int:
        """Bytes in the file (after a write failure: up to the end of the last complete chunk)."""
        return self._stream.tell()

    @property
    def error(self) -> BagWriteError | None:
        """The write failure that stopped the writer, or None."""
        return self._error

    def topics(self) -> dict[str, str]:
        """Topics added so far and their type names."""
        return {topic: stats.type_name for topic, stats in self._topics.items()}

    # -- writing --------------------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, qos_profiles_yaml: str | None = None, *,
                  type_hash: str = '', definition: str | None = None) -> int:
        """Register a topic and return its channel id (the same id again for a known topic).

        `qos_profiles_yaml` is rosbag2's `offered_qos_profiles` text (see `qos_profiles_yaml`);
        None records the contract's publisher profile (reliable, volatile, keep_last 10).
        `definition` overrides the schema text (default: `msgdefs.full_definition`).
        """
        if not topic:
            raise BagError('topic name is empty; give the full topic name like /measured_pose')
        with self._guard('add a topic'):
            known = self._topics.get(topic)
            if known is not None:
                if known.type_name != type_name:
                    raise BagError(f'topic {topic!r} was added with type {known.type_name}, '
                                   f'not {type_name}; one type per topic')
                return known.channel_id
            schema_id = self._schemas.get(type_name)
            if schema_id is None:
                text = definition if definition is not None else full_definition(type_name)
                schema_id = self._mcap.register_schema(type_name, SCHEMA_ENCODING,
                                                       text.encode('utf-8'))
                self._schemas[type_name] = schema_id
            qos_yaml = DEFAULT_QOS_YAML if qos_profiles_yaml is None else qos_profiles_yaml
            metadata = {'offered_qos_profiles': qos_yaml, 'topic_type_hash': type_hash}
            channel_id = self._mcap.register_channel(topic, MESSAGE_ENCODING, schema_id,
                                                     metadata)
            stats = _TopicStats(channel_id, type_name, qos_yaml, type_hash)
            self._topics[topic] = stats
            self._by_channel[channel_id] = stats
            return channel_id

    def write(self, channel_id: int, log_time_ns: int, data: bytes,
              publish_time_ns: int | None = None) -> None:
        """Append one serialized message (CDR bytes) to `channel_id` at `log_time_ns`."""
        if log_time_ns < 0:
            raise BagError(f'log time must be >= 0 ns, got {log_time_ns}')
        with self._guard('write'):
            if self._error is not None:
                raise self._error
            stats = self._stats_of(channel_id)
            publish = log_time_ns if publish_time_ns is None else publish_time_ns
            if self._chunk_bytes == 0:
                self._chunk_first_log_ns = log_time_ns
                self._chunk_wall_start = time.monotonic()
            self._mcap.add_message(channel_id, log_time_ns, bytes(data), publish)
            stats.message_count += 1
            self._message_count += 1
            self._chunk_messages += 1
            self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns,
                                                                            log_time_ns)
            self._end_ns = max(self._end_ns, log_time_ns)
            self._chunk_bytes += len(data) + _MESSAGE_RECORD_OVERHEAD
            if self._chunk_is_full(log_time_ns):
                self._finish_chunk()

    def flush(self) -> None:
        """Finish the open chunk so it is on disk (call at least every max_chunk_duration).

        Does nothing once a write failure stopped the writer.
        """
        with self._guard('flush'):
            if self._chunk_bytes and self._error is None:
                self._finish_chunk()

    def close(self) -> None:
        """Write the rosbag2 metadata record, the summary and the footer; close the file.

        Idempotent. From a signal handler that interrupted a write on this thread, the close is
        done right after that write returns. After a write failure it only closes the file; a
        failure while writing the summary raises `BagWriteError` (the file then ends at the last
        complete chunk, like one from a killed writer).
        """
        if self._closed:
            return
        if not self._lock.acquire(blocking=False):
            owner = self._owner
            if owner is None or owner == threading.get_ident():
                # Re-entered from a signal handler (or the holder is just entering): the
                # current holder closes when its call ends.
                self._close_requested = True
                return
            self._lock.acquire()
        try:
            self._close_locked()
        finally:
            self._lock.release()

    # -- internals ------------------------------------------------------------------------
    def _guard(self, action: str) -> _Guard:
        return _Guard(self, action)

    def _stats_of(self, channel_id: int) -> _TopicStats:
        stats = self._by_channel.get(channel_id)
        if stats is None:
            raise BagError(f'unknown channel id {channel_id}; use the id add_topic() returned')
        return stats

    def _chunk_is_full(self, log_time_ns: int) -> bool:
        return (self._chunk_bytes >= self.chunk_size
                or abs(log_time_ns - self._chunk_first_log_ns) >= self._max_chunk_ns
                or time.monotonic() - self._chunk_wall_start >= self.max_chunk_duration)

    def _finish_chunk(self) -> None:
        try:
            self._mcap.flush()
        except OSError as err:
            raise self._stop_writing(err) from None
        self._chunk_bytes = 0
        self._chunk_messages = 0
        self._good_offset = self._stream.tell()

    def _stop_writing(self, err: OSError) -> BagWriteError:
        """Record a write failure: cut the partial chunk off, count its messages as lost."""
        try:
            self._stream.truncate(self._good_offset)
        except OSError:
            pass  # the partial record stays; readers stop at it
        self._lost_count = self._chunk_messages
        self._chunk_messages = self._chunk_bytes = 0
        kept = self.bytes_written
        reason = err.strerror or str(err)
        if err.errno in DISK_FULL_ERRNOS:
            what = f'disk full ({reason})'
            advice = 'free space (or raise the file-size limit)'
        else:
            what = f'write error ({reason})'
            advice = 'check the disk'
        self._error = BagWriteError(
            f'{what}: stopped writing bag {str(self.path)!r} after {kept} bytes; '
            f'{self._message_count - self._lost_count} messages are in the file, '
            f'{self._lost_count} of the open chunk are lost and later ones are not written; '
            f'{advice}, then run recover() on the file for a finished copy',
            path=self.path, bytes_kept=kept, errno_value=err.errno)
        return self._error

    def _close_locked(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._error is not None:
            self._stream.close()  # no summary can be written; the file ends at a chunk
            return
        try:
            if self._chunk_bytes:
                self._finish_chunk()
            self._mcap.add_metadata(METADATA_NAME, {METADATA_KEY: self._metadata_yaml()})
            self._mcap.finish()
        except OSError as err:
            raise self._stop_writing(err) from None
        finally:
            self._stream.close()

    def _metadata_yaml(self) -> str:
        """rosbag2 v9 bag metadata (metadata.yaml content without its top-level key)."""
        start = self._start_ns or 0
        duration = self._end_ns - start if self._message_count else 0
        topics = [
            {
                'topic_metadata': {
                    'name': topic,
                    'type': stats.type_name,
                    'serialization_format': MESSAGE_ENCODING,
                    'offered_qos_profiles': yaml.safe_load(stats.qos_yaml) or [],
                    'type_description_hash': stats.type_hash,
                },
                'message_count': stats.message_count,
            }
            for topic, stats in self._topics.items()
        ]
        metadata = {
            'version': ROSBAG2_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self._message_count,
            'topics_with_message_count': topics,
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.path.name],
            'files': [{
                'path': self.path.name,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': duration},
                'message_count': self._message_count,
            }],
            'custom_data': dict(self._custom_data),
            'ros_distro': ROS_DISTRO,
        }
        text: str = yaml.safe_dump(metadata, sort_keys=False, default_flow_style=False)
        return text


def _checked_custom_data(values: Mapping[str, str]) -> dict[str, str]:
    """A copy of rosbag2 custom data after checking it is a map of non-empty str to str."""
    for key, value in values.items():
        if not (isinstance(key, str) and key and isinstance(value, str)):
            raise BagError(f'custom_data must map non-empty strings to strings (rosbag2 '
                           f'metadata), got {key!r}: {value!r}; convert the value with str()')
    return dict(values)


class _Guard:
    """Serialize writer calls, refuse calls after close, run a close deferred by a signal."""

    def __init__(self, writer: BagWriter, action: str) -> None:
        self._writer = writer
        self._action = action

    def __enter__(self) -> None:
        writer = self._writer
        writer._lock.acquire()
        if writer._closed:
            writer._lock.release()
            raise BagError(f'cannot {self._action}: bag {str(writer.path)!r} is closed')
        writer._owner = threading.get_ident()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        writer = self._writer
        writer._owner = None
        try:
            if writer._close_requested:
                writer._close_locked()
        finally:
            writer._lock.release()
