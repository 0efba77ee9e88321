"""The messages' constants are the shared table's (frog_common.primitives)."""

from frog_common.primitives import LIMB_IDS, PRIMITIVE_BITS, PRIMITIVE_IDS
from soft_robot_interfaces.msg import LimbActivation, Primitive


def test_primitive_constants_equal_the_table():
    ids = {name[3:]: getattr(Primitive, name) for name in dir(Primitive)
           if name.startswith("ID_") and name != "ID_MAX"}
    assert ids == PRIMITIVE_IDS
    assert Primitive.ID_MAX == max(PRIMITIVE_IDS.values()) == len(PRIMITIVE_BITS) - 1


def test_limb_constants_equal_the_table():
    limbs = {name[5:]: getattr(LimbActivation, name) for name in dir(LimbActivation) if name.startswith("LIMB_")}
    assert limbs == LIMB_IDS


def test_the_message_files_bit_table_is_the_shared_one():
    import re
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / "ros_ws/src/soft_robot_interfaces/msg/Primitive.msg").read_text()
    rows = {name: (int(i), bits) for i, name, bits in re.findall(r"(\d)\s+([A-I])\s+([01]{4})", text)}
    assert {n: b for n, (_, b) in rows.items()} == PRIMITIVE_BITS
    assert {n: i for n, (i, _) in rows.items()} == PRIMITIVE_IDS


def test_the_tracker_and_planner_state_codes_are_the_messages():
    from frog_planner.core import decision_loop
    from frog_vision.core import tracking_state
    from soft_robot_interfaces.msg import PlannerStatus, TrackerState
    for name in ("SEARCHING", "TRACKING", "COASTING", "LOST", "FROZEN"):
        assert getattr(tracking_state, name) == getattr(TrackerState, f"STATE_{name}")
    assert tracking_state.STATE_NAMES[TrackerState.STATE_COASTING] == "coasting"
    for name in ("IDLE", "FOLLOWING", "GOAL_REACHED", "WAITING", "ERROR"):
        assert getattr(decision_loop, name) == getattr(PlannerStatus, f"STATE_{name}")
