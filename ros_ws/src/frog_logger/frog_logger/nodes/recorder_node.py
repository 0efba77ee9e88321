"""``recorder``: rosbag-free recording of raw CDR messages to MCAP.

Subscribes to the topics given in ``topics`` (or to every visible topic, re-discovered
while running) with ``raw=True`` so messages are written without deserialising, matches
each topic's publishers' QoS, and hands the bytes to :class:`frog_logger.core.Recording`.
Existing files are never overwritten or truncated: restarted with the same ``output_dir``
and ``file_prefix`` (after a crash, by a supervisor), it starts the next numbered file.
"""

from __future__ import annotations

import importlib
import json
import re
import sys
import time

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from soft_robot_common import ConfigurationError, NodeDiagnostics, Param, declare_parameters, run_node
from soft_robot_common.diagnostics import ERROR, OK

from frog_logger.core.message_definitions import MessageDefinitionError, full_message_definition
from frog_logger.core.recording import Recording, RecordingError

_PARAMS = [
    Param("topics", [""], "topics to record; empty (or ['']) records every topic and keeps discovering new "
          "ones; relative names resolve in the recorder's namespace"),
    Param("exclude_regex", "", "topics matching this regular expression are not recorded (all-topics mode)"),
    Param("include_hidden", False, "also record hidden topics (a name part starting with '_')"),
    Param("output_dir", "recordings", "folder for the MCAP files (created if missing)"),
    Param("file_prefix", "", "file name prefix; files are <prefix>_000.mcap, ... (empty: rec_<date>_<time>); a "
          "restart with the same folder and prefix continues after the highest existing number"),
    Param("max_file_size_mb", 0.0, "start a new file past this size [MB = 1e6 bytes]; 0 = no size split",
          min=0.0, max=1e7),
    Param("max_file_duration_s", 0.0, "start a new file after this duration [s]; 0 = no time split", min=0.0,
          max=1e7),
    Param("compression", "zstd", "chunk compression", choices=("zstd", "lz4", "none")),
    Param("flush_period_s", 0.5, "close the open chunk this often [s]: the most a SIGKILL can lose", min=0.01,
          max=3600.0),
    Param("discovery_period_s", 0.5, "how often to look for new topics and publishers [s]", min=0.05, max=3600.0),
    Param("history", "keep_all", "subscription history: keep_all (DDS buffers a backlog without loss while the "
          "recorder is busy) or keep_last (bounded by queue_depth; old messages dropped)",
          choices=("keep_all", "keep_last")),
    Param("queue_depth", 1000, "subscription history depth per topic with history keep_last", min=1,
          max=1_000_000),
    Param("retry_period_s", 5.0, "after a write error (disk full), try a new file this often [s]", min=0.1,
          max=3600.0),
]


def _check_regex(values: dict) -> str | None:
    try:
        re.compile(values["exclude_regex"])
    except re.error as exc:
        return f"exclude_regex {values['exclude_regex']!r} is not a valid regular expression: {exc}"
    return None


def _qos_to_dict(qos) -> dict:
    def dur(d):
        return getattr(d, "nanoseconds", 0)
    return {
        "reliability": qos.reliability.name.lower(),
        "durability": qos.durability.name.lower(),
        "history": qos.history.name.lower(),
        "depth": int(qos.depth),
        "deadline_ns": dur(qos.deadline),
        "lifespan_ns": dur(qos.lifespan),
        "liveliness": qos.liveliness.name.lower(),
    }


def _message_class(type_name: str):
    pkg, kind, name = type_name.split("/")
    if kind != "msg":
        raise ImportError(f"{type_name!r} is not a message type")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


class _RawCallback:
    """Subscription callback taking (bytes, message info): rclpy passes both.

    The executor dispatches one message per wake-up, at roughly 100 us each; under load
    that, not the disk, limits a recorder. After the message it was given, the callback
    takes whatever else is already queued on the same subscription (as the executor
    itself does, through ``handle.take_message``), up to ``MAX_DRAIN`` per call so timers
    still run.
    """

    MAX_DRAIN = 500

    def __init__(self, node: "RecorderNode", topic: str):
        self.node, self.topic = node, topic
        self.subscription = None  # set once created

    def __call__(self, data, info):
        self.node.on_message(self.topic, data, info)
        sub = self.subscription
        if sub is None:
            return
        with sub.handle:
            for _ in range(self.MAX_DRAIN):
                taken = sub.handle.take_message(sub.msg_type, True)
                if taken is None:
                    break
                self.node.on_message(self.topic, taken[0], taken[1])


class RecorderNode(Node):
    """Records topics to MCAP; see the module docstring and ``ros2 param list /recorder``."""

    NODE_NAME = "recorder"

    def __init__(self, **kwargs):
        super().__init__("recorder", **kwargs)
        p = declare_parameters(self, _PARAMS, validate=_check_regex)
        try:
            self.topics = [self.resolve_topic_name(t) for t in (p["topics"] or []) if t]
        except Exception as exc:  # rclpy raises its own name-validation errors
            raise ConfigurationError(f"topics: {exc}") from None
        self.include_hidden = p["include_hidden"]
        self.exclude = re.compile(p["exclude_regex"]) if p["exclude_regex"] else None
        self.queue_depth = p["queue_depth"]
        self.history = (HistoryPolicy.KEEP_ALL if p["history"] == "keep_all"
                        else HistoryPolicy.KEEP_LAST)
        prefix = p["file_prefix"] or time.strftime("rec_%Y%m%d_%H%M%S")
        try:
            self.recording = Recording(
                p["output_dir"], prefix,
                max_file_bytes=int(p["max_file_size_mb"] * 1e6),
                max_file_duration_s=p["max_file_duration_s"],
                compression=p["compression"],
                metadata={"node": self.get_fully_qualified_name(),
                          "requested_topics": json.dumps(self.topics or "all")})
        except RecordingError as exc:
            raise ConfigurationError(str(exc)) from exc
        try:
            self._start()
        except BaseException:
            self.recording.close()  # never leave an unfinished file behind a failed start
            raise

    def _start(self) -> None:
        p = {row.name: self.get_parameter(row.name).value for row in _PARAMS}
        self._recorded: dict[str, object] = {}
        self._rejected: dict[str, str] = {}      # topic -> reason, logged once
        self._last_error_log = 0.0
        self._last_retry = 0.0
        self._retry_period = p["retry_period_s"]
        self.create_timer(p["discovery_period_s"], self.discover)
        self.create_timer(p["flush_period_s"], self.flush)
        self.diagnostics = NodeDiagnostics(self, "recording", self._diagnostics, hardware_id="")
        earlier = self.recording.existing_files
        self.get_logger().info(
            f"recording {'topics ' + ', '.join(self.topics) if self.topics else 'all topics'} "
            f"to {self.recording.current_file}"
            + (f" (after {len(earlier)} earlier file(s) of this prefix, left untouched: {earlier[-1].name} ...)"
               if earlier else ""))
        self.discover()

    # -- discovery ---------------------------------------------------------------------
    def _wanted(self, topic: str) -> bool:
        if self.topics:
            return topic in self.topics
        if not self.include_hidden and any(part.startswith("_") for part in topic.split("/")):
            return False
        return not (self.exclude and self.exclude.search(topic))

    def discover(self) -> None:
        """Subscribe to wanted topics that have publishers and are not yet recorded."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self._rejected or not self._wanted(topic):
                continue
            if len(types) != 1:
                self._reject(topic, f"it has several types {types}; cannot record one channel")
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            self._subscribe(topic, types[0], infos)

    def _reject(self, topic: str, reason: str) -> None:
        self._rejected[topic] = reason
        self.get_logger().error(f"not recording {topic}: {reason}")

    def _subscribe(self, topic: str, type_name: str, infos) -> None:
        try:
            msg_class = _message_class(type_name)
            definition = full_message_definition(type_name)
        except (ImportError, AttributeError, ValueError, MessageDefinitionError) as exc:
            self._reject(topic, f"unknown message type {type_name!r} ({exc})")
            return
        offered = [i.qos_profile for i in infos]
        reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        qos = QoSProfile(
            history=self.history, depth=self.queue_depth,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
        self.recording.add_topic(topic, type_name, definition,
                                 {"offered": [_qos_to_dict(q) for q in offered],
                                  "subscribed": _qos_to_dict(qos)})
        callback = _RawCallback(self, topic)
        callback.subscription = self._recorded[topic] = self.create_subscription(
            msg_class, topic, callback, qos, raw=True)
        self.get_logger().info(f"recording {topic} [{type_name}] "
                               f"({qos.reliability.name.lower()}, {qos.durability.name.lower()})")

    # -- data --------------------------------------------------------------------------
    def on_message(self, topic: str, data: bytes, info) -> None:
        now = time.time_ns()
        published = info.get("source_timestamp") if isinstance(info, dict) else None
        if not self.recording.write(topic, data, now, published):
            self._log_write_error()

    def flush(self) -> None:
        if self.recording.error is None:
            if not self.recording.flush():
                self._log_write_error()
            return
        now = time.monotonic()
        if now - self._last_retry >= self._retry_period:
            self._last_retry = now
            if self.recording.retry():
                self.get_logger().warning(
                    f"recording again into {self.recording.current_file} after a write error; "
                    f"{self.recording.dropped_messages} messages were lost meanwhile")

    def _log_write_error(self) -> None:
        now = time.monotonic()
        if now - self._last_error_log >= 2.0:
            self._last_error_log = now
            self.get_logger().error(
                f"{self.recording.error}; {self.recording.dropped_messages} messages dropped so "
                f"far; will retry in a new file every {self._retry_period:g} s "
                f"(salvage the broken file with: frog-log recover)")

    def _diagnostics(self):
        """(level, message, values): the file, counts per topic (``messages <topic>`` for every topic
        subscribed: the typed record of what is recorded), drops; ``ready`` once every topic asked
        for in ``topics`` is subscribed (all-topics mode: at once)."""
        rec = self.recording
        values = {"file": str(rec.current_file), "messages": rec.message_count,
                  "dropped_messages": rec.dropped_messages, "files": len(rec.files),
                  "ready": all(t in self._recorded for t in self.topics)}
        values.update({f"messages {t.name}": t.message_count for t in rec.topics.values()})
        return (ERROR if rec.error else OK), rec.error or f"recording {len(rec.topics)} topics", values

    def close(self) -> None:
        rec = self.recording
        try:
            rec.close()
        except RecordingError as exc:
            self.get_logger().error(str(exc))
        counts = ", ".join(f"{t.name}: {t.message_count}" for t in rec.topics.values())
        if rec.message_count == 0:
            self.get_logger().warning(f"no messages were recorded (files: {rec.files})")
        self.get_logger().info(f"closed {len(rec.files)} file(s) {[str(f) for f in rec.files]}; "
                               f"{rec.message_count} messages ({counts}); "
                               f"dropped {rec.dropped_messages}")


def main(args=None) -> int:
    return run_node(RecorderNode, args, close=RecorderNode.close)


if __name__ == "__main__":
    sys.exit(main())
