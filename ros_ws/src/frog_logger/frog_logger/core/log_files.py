"""Reading our MCAP recordings without ROS: summary, CSV export, decode check, recovery.

All functions decode with ``mcap_ros2`` from the ``ros2msg`` schemas stored in the file,
so they work on any machine with the ``mcap`` packages, with or without ROS installed.
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer
from mcap_ros2.decoder import DecoderFactory

__all__ = ["LogFileError", "TopicSummary", "FileSummary", "summarize", "check",
           "export_csv", "flatten_message", "recover", "read_messages"]


class LogFileError(RuntimeError):
    """A recording cannot be read (missing, not MCAP, truncated where that matters)."""


@dataclass
class TopicSummary:
    topic: str
    type_name: str
    message_count: int = 0
    first_ns: Optional[int] = None
    last_ns: Optional[int] = None


@dataclass
class FileSummary:
    path: Path
    complete: bool                 # False: the file was not closed (crash); run recover
    topics: dict[str, TopicSummary] = field(default_factory=dict)
    metadata: dict[str, dict] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())

    @property
    def start_ns(self) -> Optional[int]:
        times = [t.first_ns for t in self.topics.values() if t.first_ns is not None]
        return min(times) if times else None

    @property
    def end_ns(self) -> Optional[int]:
        times = [t.last_ns for t in self.topics.values() if t.last_ns is not None]
        return max(times) if times else None

    @property
    def duration_s(self) -> float:
        if self.start_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9


def _open(path) -> Path:
    p = Path(path)
    if not p.is_file():
        raise LogFileError(f"{str(p)!r} does not exist or is not a file")
    with open(p, "rb") as f:
        magic = f.read(8)
    if magic != b"\x89MCAP0\r\n":
        raise LogFileError(f"{str(p)!r} is not an MCAP file (bad magic bytes)")
    return p


def _stream_records(path: Path) -> tuple[list, bool]:
    """All complete records of a possibly truncated file, and whether it ended cleanly."""
    records = []
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False, emit_chunks=False).records:
                records.append(record)
        except (McapError, EOFError, ValueError, OSError, Exception):  # noqa: B014
            # Truncated at a crash: everything before the broken record is kept.
            return records, False
    return records, True


def summarize(path) -> FileSummary:
    """Topics, message counts, time span and metadata of one recording."""
    p = _open(path)
    records, clean = _stream_records(p)
    summary = FileSummary(p, complete=clean)
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    for r in records:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
            schema = schemas.get(r.schema_id)
            summary.topics.setdefault(r.topic, TopicSummary(
                r.topic, schema.name if schema else "?"))
        elif isinstance(r, Message):
            t = summary.topics[channels[r.channel_id].topic]
            t.message_count += 1
            t.first_ns = r.log_time if t.first_ns is None else min(t.first_ns, r.log_time)
            t.last_ns = r.log_time if t.last_ns is None else max(t.last_ns, r.log_time)
        elif isinstance(r, Metadata):
            summary.metadata[r.name] = dict(r.metadata)
    return summary


def read_messages(path, topics: Optional[list[str]] = None, publish_time: bool = False) -> Iterator[tuple]:
    """Yield ``(topic, log_time_ns, decoded_message)`` in file order; with ``publish_time``,
    ``(topic, log_time_ns, publish_time_ns, decoded_message)``.

    ``log_time`` is when the recorder received the message, ``publish_time`` when its publisher
    wrote it (the DDS source timestamp; the receive time where the middleware gave none).

    Raises
    ------
    LogFileError
        On a file that is not MCAP or not closed cleanly (suggesting ``recover``).
    """
    p = _open(path)
    with open(p, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        try:
            for schema, channel, message, decoded in reader.iter_decoded_messages(
                    topics=topics, log_time_order=False):
                if publish_time:
                    yield channel.topic, message.log_time, message.publish_time, decoded
                else:
                    yield channel.topic, message.log_time, decoded
        except McapError as exc:
            raise LogFileError(f"{str(p)!r} cannot be read to the end ({exc}); if the "
                               f"recorder was killed, run: frog-log recover {p}") from exc


@dataclass
class CheckResult:
    path: Path
    decoded: int = 0
    failures: list[str] = field(default_factory=list)
    complete: bool = True

    @property
    def ok(self) -> bool:
        return self.complete and not self.failures


def check(path) -> CheckResult:
    """Decode every message of a recording; collect per-message failures (never raises
    for bad messages, only for a file that is not MCAP)."""
    p = _open(path)
    result = CheckResult(p)
    records, result.complete = _stream_records(p)
    if not result.complete:
        result.failures.append("file is truncated (recorder killed?); run frog-log recover")
    factory = DecoderFactory()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    decoders: dict[int, object] = {}
    for r in records:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
        elif isinstance(r, Message):
            ch = channels.get(r.channel_id)
            if ch is None:
                result.failures.append(f"message for unknown channel {r.channel_id}")
                continue
            try:
                dec = decoders.get(ch.id)
                if dec is None:
                    dec = factory.decoder_for(ch.message_encoding, schemas.get(ch.schema_id))
                    if dec is None:
                        raise ValueError(f"no ros2msg/cdr decoder for channel {ch.topic}")
                    decoders[ch.id] = dec
                dec(r.data)
                result.decoded += 1
            except Exception as exc:  # any decode failure is a finding, not a crash
                if len(result.failures) < 20:
                    result.failures.append(f"{ch.topic} message {r.sequence}: {exc}")
                else:
                    result.failures.append("...")
    return result


def flatten_message(msg, prefix: str = "") -> dict:
    """Flatten a decoded ROS message into ``{"a.b.c": scalar}`` columns.

    Fixed or variable sequences of numbers become ``field[i]`` columns; sequences of
    messages become ``field[i].sub`` columns; bytes become hex.
    """
    out: dict = {}
    slots = getattr(msg, "__slots__", None)
    if slots is None:
        fields = list(vars(msg)) if hasattr(msg, "__dict__") else []
    else:
        fields = [s for s in slots if not s.startswith("_")]
    for name in fields:
        value = getattr(msg, name)
        key = f"{prefix}{name}"
        _flatten_value(value, key, out)
    return out


def _flatten_value(value, key: str, out: dict) -> None:
    if isinstance(value, (bytes, bytearray)):
        out[key] = bytes(value).hex()
    elif isinstance(value, (list, tuple)) or type(value).__name__ == "ndarray":
        for i, item in enumerate(value):
            _flatten_value(item, f"{key}[{i}]", out)
        if len(value) == 0:
            out[key] = ""
    elif hasattr(value, "__slots__") or (hasattr(value, "__dict__")
                                         and not isinstance(value, (int, float, str))):
        out.update(flatten_message(value, key + "."))
    else:
        out[key] = value


def export_csv(path, out_dir, topics: Optional[list[str]] = None) -> dict[str, Path]:
    """Write one CSV per topic with ``log_time_ns`` and flattened fields.

    Returns a mapping topic -> CSV path. A topic whose messages change shape (variable
    arrays) gets the union of all columns; missing cells are empty.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows: dict[str, list[dict]] = defaultdict(list)
    for topic, log_time, decoded in read_messages(path, topics):
        row = {"log_time_ns": log_time}
        row.update(flatten_message(decoded))
        rows[topic].append(row)
    written = {}
    for topic, topic_rows in rows.items():
        columns: dict[str, None] = {}
        for row in topic_rows:
            columns.update(dict.fromkeys(row))
        name = topic.strip("/").replace("/", "__") or "root"
        csv_path = out_dir / f"{name}.csv"
        with open(csv_path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(columns), restval="")
            writer.writeheader()
            for row in topic_rows:
                writer.writerow({k: _csv_cell(v) for k, v in row.items()})
        written[topic] = csv_path
    return written


def _csv_cell(v):
    if isinstance(v, float) and math.isfinite(v):
        return repr(v)  # shortest round-trip representation
    return v


def recover(path, out_path) -> tuple[int, bool]:
    """Rewrite a (possibly truncated) recording into a complete, indexed MCAP file.

    Returns ``(messages recovered, input was complete)``. Every message of every complete
    chunk is kept; a partly written last chunk is dropped (at most the last flush period).
    """
    p = _open(path)
    out = Path(out_path)
    if out.exists():
        raise LogFileError(f"refusing to overwrite {str(out)!r}")
    records, clean = _stream_records(p)
    n = 0
    with open(out, "xb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="frog_logger recover")
        schema_map: dict[int, int] = {}
        channel_map: dict[int, int] = {}
        for r in records:
            # A complete file repeats schemas and channels in its summary: keep the first.
            if isinstance(r, Schema) and r.id not in schema_map:
                schema_map[r.id] = writer.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel) and r.id not in channel_map:
                channel_map[r.id] = writer.register_channel(
                    r.topic, r.message_encoding, schema_map.get(r.schema_id, 0),
                    dict(r.metadata))
            elif isinstance(r, Message) and r.channel_id in channel_map:
                writer.add_message(channel_map[r.channel_id], r.log_time, r.data,
                                   r.publish_time, r.sequence)
                n += 1
            elif isinstance(r, Metadata):
                writer.add_metadata(r.name, dict(r.metadata))
        writer.add_metadata("recovery", {"source": str(p), "source_complete": json.dumps(clean),
                                         "messages_recovered": str(n)})
        writer.finish()
    return n, clean
