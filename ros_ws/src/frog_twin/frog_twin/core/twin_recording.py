"""A twin run's MCAP recording as arrays: truth, tracked poses, decisions, serial lines, firings.

Everything is read back from the recording (nothing from the processes' memory), so the
figures a twin run prints can be recomputed by anyone from its MCAP file. Times are header
stamps in seconds (simulated time in the twin).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from frog_logger.core.log_files import read_messages, recover, summarize
from frog_common.se2 import yaw_of

#: Topics the analysis reads (root namespace).
TOPICS = {
    "truth": "/frog/sim/odom", "tracked": "/frog/odom", "status": "/frog/planner/status",
    "primitive": "/frog/primitive", "sent": "/frog/bridge/sent", "fired": "/frog/limb_activation",
    "path": "/frog/path", "shape": "/frog/sim/shape", "preview": "/camera/preview/compressed",
    "camera_info": "/camera/camera_info", "tf": "/tf",
}


def _t(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


@dataclass
class TwinRecording:
    """Arrays of one run; empty arrays for topics that were not recorded."""

    truth: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))     # t, x, y, heading
    tracked: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))   # t, x, y, heading
    status: np.ndarray = field(default_factory=lambda: np.zeros((0, 10)))
    # status columns: t, primitive id, total cost, cost distance, heading, progress, path progress,
    # distance to path, state, state age
    primitives: list = field(default_factory=list)   # (t, name)
    sent: list = field(default_factory=list)         # (t, limbs)
    fired: list = field(default_factory=list)        # (t, limbs)
    path: np.ndarray | None = None                   # (M, 2)
    shapes: list = field(default_factory=list)       # (t, (K, 2) segment end points)
    preview: list = field(default_factory=list)      # (t, JPEG bytes)
    camera_info: object = None                       # last sensor_msgs/CameraInfo
    tf_frames: dict = field(default_factory=dict)    # (parent, child) -> number of transforms


def read_twin_recording(mcap_files, with_images: bool = True) -> TwinRecording:
    """Collect the run's topics from one or more MCAP files (split recordings) in time order."""
    rec = TwinRecording()
    truth, tracked, status = [], [], []
    wanted = [v for k, v in TOPICS.items() if with_images or k != "preview"]
    for f in mcap_files:
        for topic, _, m in read_messages(f, topics=wanted):
            if topic == TOPICS["truth"]:
                p = m.pose.pose.position
                truth.append([_t(m.header.stamp), p.x, p.y, yaw_of(m.pose.pose.orientation)])
            elif topic == TOPICS["tracked"]:
                p = m.pose.pose.position
                tracked.append([_t(m.header.stamp), p.x, p.y, yaw_of(m.pose.pose.orientation)])
            elif topic == TOPICS["status"]:
                status.append([_t(m.header.stamp), m.primitive_id, m.total_cost, m.cost_distance, m.cost_heading,
                               m.cost_progress, m.path_progress, m.distance_to_path, m.state, m.state_age])
            elif topic == TOPICS["primitive"]:
                rec.primitives.append((_t(m.header.stamp), m.name))
            elif topic == TOPICS["sent"]:
                rec.sent.append((_t(m.header.stamp), list(m.limbs)))
            elif topic == TOPICS["fired"]:
                rec.fired.append((_t(m.header.stamp), list(m.limbs)))
            elif topic == TOPICS["path"]:
                rec.path = np.array([[q.pose.position.x, q.pose.position.y] for q in m.poses])
            elif topic == TOPICS["shape"]:
                rec.shapes.append((_t(m.header.stamp), np.array([[q.x, q.y] for q in m.points])))
            elif topic == TOPICS["preview"]:
                rec.preview.append((_t(m.header.stamp), bytes(m.data)))
            elif topic == TOPICS["camera_info"]:
                rec.camera_info = m
            elif topic == TOPICS["tf"]:
                for tr in m.transforms:
                    key = (tr.header.frame_id, tr.child_frame_id)
                    rec.tf_frames[key] = rec.tf_frames.get(key, 0) + 1
    order = lambda rows, width: np.array(sorted(rows), dtype=float).reshape(-1, width)  # noqa: E731
    rec.truth, rec.tracked, rec.status = order(truth, 4), order(tracked, 4), order(status, 10)
    for name in ("primitives", "sent", "fired", "shapes", "preview"):
        getattr(rec, name).sort(key=lambda item: item[0])
    return rec


def recordings(folder) -> set:
    """The MCAP files in ``folder`` now (what a run's recorder must not be read with)."""
    return set(Path(folder).glob("*.mcap"))


def run_files(folder, before) -> list:
    """This run's MCAP files in ``folder``, in order: those not in ``before`` (:func:`recordings`
    taken at the run's start; a recorder never overwrites, so an earlier run's files stay)."""
    return sorted(f for f in Path(folder).glob("*.mcap") if f not in before)


def readable_files(mcap_files, recovered_dir) -> list:
    """The files, with each one cut short by a killed recorder replaced by its recovered copy.

    The copy (``frog-log recover``: every complete chunk) goes to ``recovered_dir``; the
    recorder's own files are left as they are.
    """
    out = []
    for f in mcap_files:
        if summarize(f).complete:
            out.append(f)
            continue
        target = Path(recovered_dir) / Path(f).name
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            recover(f, target)
        out.append(target)
    return out


def recorded_stamps(mcap_files, topics) -> dict:
    """{topic: [header stamp]} of every message of ``topics`` in the files (the recorder's completeness)."""
    out = {t: [] for t in topics}
    for f in mcap_files:
        for topic, _, m in read_messages(f, topics=list(topics)):
            out[topic].append(_t(m.header.stamp))
    return out


def read_pulse_ages(mcap_files, bound_s: float):
    """The :class:`~frog_twin.core.state_audit.PulseAges` of a recording: the state behind every pulse
    on frog/bridge/sent, from the recorded odometry and tracker states (see that module)."""
    from frog_twin.core.state_audit import measured_poses, pulse_ages
    odom, states, pulses = [], {}, []
    seen_states = False
    for f in mcap_files:
        for topic, log_ns, pub_ns, m in read_messages(f, ["/frog/odom", "/frog/tracker/state", "/frog/bridge/sent"],
                                                      publish_time=True):
            if topic == "/frog/odom":
                odom.append((_t(m.header.stamp), pub_ns * 1e-9, log_ns * 1e-9))
            elif topic == "/frog/tracker/state":
                seen_states = True
                states[round(_t(m.header.stamp), 6)] = _t(m.state_stamp)
            elif len(m.limbs):
                pulses.append((pub_ns * 1e-9, log_ns * 1e-9, float(m.state_age), _t(m.header.stamp)))
    return pulse_ages(pulses, measured_poses(odom, states if seen_states else None), bound_s)
