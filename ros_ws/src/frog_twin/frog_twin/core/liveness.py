"""Is a running tracker still hearing its camera? (issue 22: a live process can be deaf.)

A tracker process can be alive and receive nothing: after a SIGSTOP/SIGCONT, or after its
camera was restarted, Fast DDS sometimes never delivers to it again (docs/faults.md). Its
process runs, so the supervisor sees no exit. The two nodes' diagnostics (1 Hz on their wall
clocks) tell it: the camera's count of published frames goes up while the tracker's count of
received frames does not (or its diagnostics stop arriving: an executor that runs nothing).

:class:`DeafWatch` is fed both counts with their arrival times and says when the tracker has
heard nothing for ``bound_s`` while the camera published at least ``min_frames``. Times when
silence is expected (the tracker or camera down or restarting, the tracker SIGSTOPped on
purpose) are excused: the wait starts again after them. Pure Python (no rclpy).
"""

from __future__ import annotations

from dataclasses import dataclass

#: Tracker silence [s of wall time] with the camera publishing that counts as deaf. Above the
#: longest SIGSTOP of the campaign (4 s) and the 1 Hz diagnostics' jitter under load.
DEAF_AFTER_S = 8.0
#: Frames the camera must have published in that time (not a camera that is itself stalled).
DEAF_MIN_FRAMES = 10


@dataclass
class DeafWatch:
    """Tracks the camera's published and the tracker's received frame counts (see the module)."""

    bound_s: float = DEAF_AFTER_S
    min_frames: int = DEAF_MIN_FRAMES
    _since: float | None = None          # last time the tracker heard a frame (or the wait restarted)
    _published: int = 0                  # camera frames published since then
    _camera_last: int | None = None
    _tracker_last: int | None = None

    def __post_init__(self):
        if not (self.bound_s > 0 and self.min_frames >= 1):
            raise ValueError(f"deaf tracker check: need bound_s > 0 and min_frames >= 1, got {self.bound_s}, "
                             f"{self.min_frames}")

    def restart(self, now: float) -> None:
        """Start waiting again from ``now`` (an excuse ended, the tracker was restarted)."""
        self._since = now
        self._published = 0

    def camera(self, now: float, frames: int) -> None:
        """The camera's diagnostics: ``frames`` published so far (a smaller count: a new process)."""
        last = self._camera_last
        self._camera_last = frames
        if self._since is None:
            self.restart(now)
            return
        self._published += frames - last if last is not None and frames >= last else frames

    def tracker(self, now: float, frames: int) -> None:
        """The tracker's diagnostics: ``frames`` received so far (another count, larger or, from a new
        process, smaller, means it hears)."""
        last = self._tracker_last
        self._tracker_last = frames
        if self._since is None or frames != last:
            self.restart(now)

    def deaf_for(self, now: float, excused: bool) -> float | None:
        """Seconds the tracker has heard nothing while the camera published ``min_frames`` or more,
        once that is at least ``bound_s``; else None. ``excused``: silence is expected now (the
        wait starts again after it)."""
        if excused:
            self.restart(now)
            return None
        if self._since is None:
            return None
        silent = now - self._since
        if silent >= self.bound_s and self._published >= self.min_frames:
            return silent
        return None

    @property
    def published(self) -> int:
        """Camera frames published since the tracker last heard one."""
        return self._published


#: What ``tracker_node``'s diagnostics say while it publishes poses: tracking, or coasting on its
#: prediction (which ends within its ``coast_timeout`` in tracking again or in "tag lost").
STILL_TRACKING = ("tracking", "tag not seen: coasting on the prediction")


def tracker_stuck(camera_frames: int, tracker_says: str | None, min_frames: int = DEAF_MIN_FRAMES,
                  said_at: float | None = None, last_pose_at: float | None = None) -> bool:
    """On the real robot, when no pose has come for the tag-lost bound: is the silence the tracker's?

    A working tracker that stops seeing the tag says so at once in its diagnostics (a state
    change is published without waiting for the 1 Hz tick: lost, frozen, searching). A tracker
    that hears nothing, or whose executor is blocked inside the middleware (seen once after its
    restart: the main thread in rclpy's ``take`` for more than 8 s, docs/faults.md), says nothing
    more, and its last word is still one of :data:`STILL_TRACKING`. So it is stuck when the camera
    published ``camera_frames`` >= ``min_frames`` since the last pose and the tracker's last word
    is one of those, or there is none (``tracker_says`` None).

    A pose is a word too: one that arrived (``last_pose_at``) after the last diagnostics message
    (``said_at``, same clock) says the tracker was tracking. A restarted tracker says "searching"
    until its first detection, and one stopped between its first pose and the "tracking" it
    publishes next has only the pose to show for it (seen under load, docs/faults.md).
    """
    if said_at is not None and last_pose_at is not None and last_pose_at > said_at:
        tracker_says = STILL_TRACKING[0]
    return camera_frames >= min_frames and (tracker_says is None or tracker_says in STILL_TRACKING)


#: Wall seconds without ``/clock`` advancing, while nothing pauses it, after which the simulated
#: world counts as stalled. Below a restarted tracker's 15 s to log its camera model: a blocked
#: world also starves every restarted vision node of /clock, which must not spend their restarts.
WORLD_STALL_S = 10.0


@dataclass
class ClockWatch:
    """Is the simulated world still running? ``/clock`` is its heartbeat (sim_node publishes it as it
    steps); once seen (session 26's series) sim_node blocked for good inside the middleware's
    ``publish`` after another node's process was SIGKILLed, and time stopped for every node.

    :meth:`stalled_for` is fed the newest ``/clock`` with the wall time; a pause on purpose (the
    ``clock_stall`` fault, a SIGSTOPped sim_node) is excused, and the wait starts again after it.
    """

    bound_s: float = WORLD_STALL_S
    _sim: float | None = None            # newest /clock [s]
    _since: float | None = None          # wall time it last advanced (or an excuse ended)

    def __post_init__(self):
        if not self.bound_s > 0:
            raise ValueError(f"world stall check: need bound_s > 0, got {self.bound_s}")

    def stalled_for(self, now: float, sim_now: float | None, excused: bool) -> float | None:
        """Wall seconds since ``/clock`` last advanced, once that is at least ``bound_s``; else None."""
        if excused or sim_now is None or self._sim is None or sim_now > self._sim:
            self._sim = sim_now
            self._since = now
            return None
        silent = now - self._since
        return silent if silent >= self.bound_s else None


#: Messages published on a checked topic while the recorder recorded none on it, within the
#: bound, for it to count as deaf: the planner publishes a primitive and a status every period
#: (1.43 s), so 8 s carry 5 of each.
RECORDER_DEAF_MIN_MESSAGES = 3


@dataclass
class RecorderWatch:
    """Is the running recorder still recording what is published? A restarted recorder was once seen
    (session 29's series) subscribed in the graph and recording nothing on four topics for 30 s: the
    restarted-reader wedge of the tracker (docs/faults.md), in the recorder. Per topic a
    :class:`DeafWatch`: the watch's own count of the messages it saw against the recorder's count
    of the messages it recorded (its ``/diagnostics``: ``messages <topic>``).

    ``heard_at[topic]`` is the recorder's stamp (its clock) on the last diagnostics whose count had
    risen (None while the running process has recorded nothing on it): what was published before it
    is recorded; a deaf time starts there, or where the process subscribed.
    """

    topics: tuple
    bound_s: float = DEAF_AFTER_S
    min_messages: int = RECORDER_DEAF_MIN_MESSAGES

    def __post_init__(self):
        self._watches = {t: DeafWatch(self.bound_s, self.min_messages) for t in self.topics}
        self.heard_at = {t: None for t in self.topics}
        self._counts = {t: None for t in self.topics}

    def published(self, now: float, counts: dict) -> None:
        """The watch's own counts {topic: messages seen so far}."""
        for t, n in counts.items():
            if t in self._watches:
                self._watches[t].camera(now, n)

    def recorded(self, now: float, stamp: float, counts: dict) -> None:
        """The recorder's diagnostics: {topic: messages recorded so far} at its ``stamp``."""
        for t, n in counts.items():
            if t in self._watches:
                prev = self._counts[t]
                if prev is not None and n < prev:          # a new process: heard only if it recorded some
                    self.heard_at[t] = stamp if n > 0 else None
                elif n > (prev or 0):
                    self.heard_at[t] = stamp
                self._counts[t] = n
                self._watches[t].tracker(now, n)

    def restart(self, now: float) -> None:
        """Start waiting again (an excuse ended, the recorder was restarted)."""
        for w in self._watches.values():
            w.restart(now)

    def deaf_for(self, now: float, excused: bool, excused_topics=()) -> tuple[str, float, int] | None:
        """(topic, seconds the recorder recorded nothing on it, messages published meanwhile) for
        the first deaf topic, once that is at least ``bound_s``; else None. ``excused_topics``: the
        running recorder has not subscribed to these yet (its wait on them starts when it has)."""
        found = None
        for t, w in self._watches.items():
            silent = w.deaf_for(now, excused or t in excused_topics)
            if silent is not None and found is None:
                found = (t, silent, w.published)
        return found
