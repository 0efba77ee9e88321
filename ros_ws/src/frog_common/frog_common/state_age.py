"""How old the state behind a limb command may be: one bound for the planner and the bridge.

Every command that can fire a limb carries the capture stamp of the measurement it was
decided on (``Primitive.state_stamp``, ``LimbActivation.state_stamp``). The planner decides
nothing on a state older than ``max_state_age_s`` and the bridge, the last hop before the
hardware, refuses to write a pulse whose state is older than that at the write, whatever the
planner did. A command without a state stamp is its own state (its header stamp, or now).

The default follows from the loop's own timing (docs/faults.md, "How old a state may be"):
the planner decides on the newest pose (up to one frame interval, 33 ms at 30 Hz, old at its
tick), the tracker adds its capture-to-pose latency, the decision takes its time, and the rear
limbs fire one pulse (80 ms) after the front. In the twin on 2 shared cores
(``./dev bench state_age``) a pulse's state was 0.20-0.22 s old in the median and 0.46-0.48 s
at the 99th percentile; 0.5 s sits just above that, and a pose 0.5 s old puts the frog
(3 cm/s, 30 deg/s) 1.5 cm and 15 deg from where the planner believes it is, a third of one
period's motion.
"""

from __future__ import annotations

from dataclasses import dataclass

from frog_common.settings import Settings, setting

#: The default bound [s] (see the module docstring).
MAX_STATE_AGE_S = 0.5
#: Ages are compared to the microsecond: the difference of two float stamps carries round-off
#: (4.4 - 3.9 = 0.5000000000000004), which must not turn a state exactly at the bound into a stale one.
AGE_RESOLUTION_S = 1e-6


@dataclass(frozen=True)
class StateAgeSettings(Settings):
    """The state-age bound (planner_node's and bridge_node's parameter of the same name)."""

    max_state_age_s: float = setting(MAX_STATE_AGE_S, "a limb is fired only on a state (the capture stamp of the "
                                     "measurement a command was decided on) at most this old", min=0.01,
                                     max=60.0, unit="s", live=True)


def command_state(state_stamp: float, header_stamp: float, now: float) -> float:
    """The state a command was decided on [s]: its state stamp, else its header stamp, else ``now``
    (zero stamps are unset: a command typed by hand is its own state)."""
    if state_stamp > 0.0:
        return state_stamp
    return header_stamp if header_stamp > 0.0 else now


def older_than(age, bound: float):
    """Whether ``age`` [s] (a number or an array) exceeds ``bound`` by more than the round-off of
    two stamps' difference (:data:`AGE_RESOLUTION_S`)."""
    return age > bound + AGE_RESOLUTION_S


def state_age_problem(age: float, bound: float) -> str | None:
    """Why a state ``age`` [s] old may not drive a limb under ``bound``, or None.

    A state stamped more than ``bound`` in the future is refused too: its sender runs on
    another clock (simulated time against the system clock), so its age means nothing.

    Examples
    --------
    >>> state_age_problem(0.2, 0.5) is None
    True
    >>> state_age_problem(0.62, 0.5)
    'the state is 0.620 s old (max_state_age_s 0.5 s)'
    >>> state_age_problem(4.4 - 3.9, 0.5) is None      # exactly at the bound, with round-off
    True
    """
    if older_than(age, bound):
        return f"the state is {age:.3f} s old (max_state_age_s {bound:g} s)"
    if age < -bound:
        return (f"the state is stamped {-age:.3f} s in the future (do the sender and this node use the same "
                f"clock? use_sim_time)")
    return None
