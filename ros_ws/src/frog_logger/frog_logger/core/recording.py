"""MCAP recording of raw ROS 2 CDR messages: schemas, channels, splitting, crash safety.

A :class:`Recording` owns a sequence of MCAP files ``<prefix>_<NNN>.mcap`` in one folder.
Files already there are never touched: a recording restarted with the same folder and
prefix (a recorder killed and started again) continues after the highest existing number.
Messages arrive as serialised CDR bytes and are written without decoding. Chunks are
closed at every :meth:`Recording.flush` (the node calls it about twice a second), so a
process killed with SIGKILL leaves a file whose complete chunks survive; ``frog-log
recover`` rewrites such a file with a proper index.
"""

from __future__ import annotations

import errno
import json
import os
import re
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

from mcap.writer import CompressionType, Writer

__all__ = ["Recording", "RecordingError", "TopicInfo", "check_output_folder", "existing_files"]

LIBRARY = "frog_logger"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}


class RecordingError(RuntimeError):
    """The recording cannot be written (folder not writable, disk full, file too large)."""


@dataclass
class TopicInfo:
    """One recorded topic: name, ROS type, full ``ros2msg`` definition and QoS (as a dict)."""

    name: str
    type_name: str
    definition: str
    qos: dict = field(default_factory=dict)
    message_count: int = 0


def check_output_folder(folder: str | os.PathLike) -> Path:
    """Create ``folder`` if needed and prove it is writable; raise RecordingError if not."""
    path = Path(folder).expanduser()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordingError(f"output folder {str(path)!r} cannot be created: "
                             f"{exc.strerror or exc}") from exc
    if not path.is_dir():
        raise RecordingError(f"output folder {str(path)!r} is not a folder")
    probe = path / f".frog_logger_probe_{os.getpid()}"
    try:
        with open(probe, "wb") as f:
            f.write(b"x")
        probe.unlink()
    except OSError as exc:
        raise RecordingError(f"output folder {str(path)!r} is not writable: "
                             f"{exc.strerror or exc}") from exc
    return path


def _file_index(path: Path, prefix: str) -> int:
    return int(path.name[len(prefix) + 1:-len(".mcap")])


def existing_files(folder: str | os.PathLike, prefix: str) -> list[Path]:
    """Files ``<prefix>_<NNN>.mcap`` in ``folder``, by their number."""
    pattern = re.compile(re.escape(prefix) + r"_\d{3,}\.mcap")
    found = [p for p in Path(folder).iterdir() if pattern.fullmatch(p.name)]
    return sorted(found, key=lambda p: _file_index(p, prefix))


def _describe_os_error(exc: OSError) -> str:
    if exc.errno == errno.ENOSPC:
        return "disk full (no space left on device)"
    if exc.errno == errno.EFBIG:
        return "file too large for this file system or process limit"
    if exc.errno == errno.EDQUOT:
        return "disk quota exceeded"
    return exc.strerror or str(exc)


class Recording:
    """Writes raw CDR messages of several topics into split MCAP files.

    Parameters
    ----------
    folder : path
        Output folder (created if missing; must be writable).
    prefix : str
        File name prefix; files are ``<prefix>_000.mcap``, ``<prefix>_001.mcap``, ...
    max_file_bytes : int
        Start a new file once the current one exceeds this size (0 = never).
    max_file_duration_s : float
        Start a new file once the current one spans this long in receive time (0 = never).
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    metadata : dict of str, optional
        Extra key/values for the ``recording`` metadata record of every file.
    clock_ns : callable, optional
        Wall clock in ns (replaceable in tests).

    Raises
    ------
    RecordingError
        If the folder is unusable or the arguments are invalid.

    Files ``<prefix>_<NNN>.mcap`` already in the folder (an earlier run, or the same
    recorder before a restart) are left as they are: numbering continues after the highest.
    """

    def __init__(self, folder, prefix: str, max_file_bytes: int = 0,
                 max_file_duration_s: float = 0.0, compression: str = "zstd",
                 metadata: Optional[dict] = None,
                 clock_ns: Callable[[], int] = time.time_ns):
        if compression not in _COMPRESSION:
            raise RecordingError(f"compression {compression!r} is not one of "
                                 f"{sorted(_COMPRESSION)}")
        if max_file_bytes < 0 or max_file_duration_s < 0:
            raise RecordingError("max_file_bytes and max_file_duration_s must be >= 0, got "
                                 f"{max_file_bytes} and {max_file_duration_s}")
        if not prefix or "/" in prefix:
            raise RecordingError(f"file prefix {prefix!r} must be a non-empty file name")
        self.folder = check_output_folder(folder)
        self.prefix = prefix
        self.max_file_bytes = int(max_file_bytes)
        self.max_file_duration_ns = int(max_file_duration_s * 1e9)
        self.compression = compression
        self.metadata = {str(k): str(v) for k, v in (metadata or {}).items()}
        self._clock_ns = clock_ns
        self.topics: dict[str, TopicInfo] = {}
        self.files: list[Path] = []
        self.existing_files = existing_files(self.folder, prefix)   # left untouched; numbering continues
        self._next_index = _file_index(self.existing_files[-1], prefix) + 1 if self.existing_files else 0
        self.error: Optional[str] = None       # last write error, None while healthy
        self.dropped_messages = 0              # messages lost to write errors
        self.start_time_ns = clock_ns()
        self._writer: Optional[Writer] = None
        self._stream = None
        self._file_start_ns = 0
        self._channel_ids: dict[str, int] = {}
        self._file_counts: dict[str, int] = {}
        self._open_next_file()

    # -- files -------------------------------------------------------------------------
    @property
    def current_file(self) -> Optional[Path]:
        """Path of the file being written, or None after a failure or close."""
        return self.files[-1] if self._writer is not None else None

    def _open_next_file(self) -> None:
        while True:
            path = self.folder / f"{self.prefix}_{self._next_index:03d}.mcap"
            self._next_index += 1
            try:
                stream = open(path, "xb")      # exclusive: never truncates a file, also one made meanwhile
                break
            except FileExistsError:
                continue
            except OSError as exc:
                raise RecordingError(f"cannot start recording file {str(path)!r}: "
                                     f"{_describe_os_error(exc)}") from exc
        try:
            writer = Writer(stream, compression=_COMPRESSION[self.compression],
                            chunk_size=4 * 1024 * 1024)
            writer.start(profile="ros2", library=LIBRARY)
            now = self._clock_ns()
            writer.add_metadata("recording", {
                **self.metadata,
                "start_time_ns": str(self.start_time_ns),
                "start_time_iso": time.strftime("%Y-%m-%dT%H:%M:%S%z",
                                                time.localtime(self.start_time_ns / 1e9)),
                "file_start_time_ns": str(now),
                "host": socket.gethostname(),
                "split_index": str(len(self.files)),
                "file_index": str(self._next_index - 1),
                "units": "log_time and publish_time in ns since the Unix epoch",
            })
            stream.flush()
        except OSError as exc:
            stream.close()
            raise RecordingError(f"cannot start recording file {str(path)!r}: "
                                 f"{_describe_os_error(exc)}") from exc
        self.files.append(path)
        self._stream, self._writer = stream, writer
        self._file_start_ns = None   # log time of the file's first message
        self._channel_ids = {}
        self._file_counts = {}
        for topic in self.topics.values():
            self._register_channel(topic)

    def _finish_file(self) -> None:
        writer, stream = self._writer, self._stream
        self._writer = self._stream = None
        if writer is None:
            return
        try:
            writer.add_metadata("topics", {
                t.name: json.dumps({"type": t.type_name, "qos": t.qos,
                                    "message_count": self._file_counts.get(t.name, 0)})
                for t in self.topics.values()})
            writer.finish()
            stream.flush()
            os.fsync(stream.fileno())
        finally:
            stream.close()

    def _register_channel(self, topic: TopicInfo) -> None:
        schema_id = self._writer.register_schema(
            name=topic.type_name, encoding="ros2msg", data=topic.definition.encode())
        self._channel_ids[topic.name] = self._writer.register_channel(
            topic=topic.name, message_encoding="cdr", schema_id=schema_id,
            metadata={"offered_qos_profiles": json.dumps(topic.qos)})
        self._file_counts.setdefault(topic.name, 0)

    # -- public API --------------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, definition: str,
                  qos: Optional[dict] = None) -> None:
        """Register a topic so its messages can be written (idempotent for the same type)."""
        if name in self.topics:
            if self.topics[name].type_name != type_name:
                raise RecordingError(f"topic {name!r} is already recorded with type "
                                     f"{self.topics[name].type_name!r}, not {type_name!r}")
            return
        topic = TopicInfo(name, type_name, definition, dict(qos or {}))
        self.topics[name] = topic
        if self._writer is not None:
            self._guarded(self._register_channel, topic)

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> bool:
        """Write one serialised message; returns False if it was dropped (see ``error``)."""
        info = self.topics.get(topic)
        if info is None:
            raise KeyError(f"topic {topic!r} was not added to the recording")
        if self._writer is None:
            self.dropped_messages += 1
            return False
        if self._needs_split(log_time_ns):
            if not self._guarded(self._split):
                self.dropped_messages += 1
                return False
        ok = self._guarded(self._writer.add_message, self._channel_ids[topic], log_time_ns,
                           data, publish_time_ns if publish_time_ns else log_time_ns,
                           info.message_count & 0xFFFFFFFF)
        if ok:
            info.message_count += 1
            self._file_counts[topic] += 1
        else:
            self.dropped_messages += 1
        return ok

    def _needs_split(self, now_ns: int) -> bool:
        if self.max_file_bytes and self._stream.tell() >= self.max_file_bytes:
            return True
        if self._file_start_ns is None:
            self._file_start_ns = now_ns
        return bool(self.max_file_duration_ns
                    and now_ns - self._file_start_ns >= self.max_file_duration_ns)

    def _split(self) -> None:
        self._finish_file()
        self._open_next_file()
        self._file_start_ns = None

    def flush(self) -> bool:
        """Close the open chunk and push it to the OS, bounding what a SIGKILL can lose."""
        if self._writer is None:
            return False
        return self._guarded(self._writer.flush)

    def retry(self) -> bool:
        """After a write error, try to continue in a new file; True if recording again."""
        if self._writer is not None:
            return True
        try:
            self._open_next_file()
        except RecordingError as exc:
            self.error = str(exc)
            return False
        self.error = None
        return True

    def close(self) -> None:
        """Finish the current file (index, summary, topic metadata) and fsync it."""
        try:
            self._finish_file()
        except OSError as exc:
            self.error = f"could not finish {self.files[-1]}: {_describe_os_error(exc)}"
            raise RecordingError(self.error) from exc

    @property
    def message_count(self) -> int:
        """Messages written so far, all topics and files."""
        return sum(t.message_count for t in self.topics.values())

    def _guarded(self, fn, *args) -> bool:
        """Run a write; on an OS error stop this file, remember why, and return False."""
        try:
            fn(*args)
            return True
        except (OSError, RecordingError) as exc:
            reason = _describe_os_error(exc) if isinstance(exc, OSError) else str(exc)
            path = self.files[-1] if self.files else self.folder
            self.error = f"writing {str(path)!r} failed: {reason}"
            stream, self._writer, self._stream = self._stream, None, None
            try:
                if stream is not None:
                    stream.close()
            except OSError:
                pass  # the file is already broken; `frog-log recover` salvages its chunks
            return False
