"""RolloutClient.expander: a response's rows become the search's tree, or a reason (no ROS graph)."""
from types import SimpleNamespace

import numpy as np
import pytest

from frog_planner.core.tree_search import tree_from_rows
from frog_planner.nodes.rollout_client import RolloutClient

NAMES = list("ABCDEFGHI")


def _response(rows, success=True, names=NAMES, message=""):
    return SimpleNamespace(success=success, message=message, primitive_names=names,
                           transitions=np.asarray(rows, float).ravel().tolist())


@pytest.mark.parametrize("depth", [1, 2])
def test_good_rows_give_the_tree_of_those_rows(depth):
    rng = np.random.default_rng(2)
    rows = rng.normal(0, 0.01, (sum(9 ** (d + 1) for d in range(depth)), 6))
    expand, reason = RolloutClient.expander(_response(rows), NAMES, depth)
    assert reason is None
    pose = np.array([0.1, -0.2, 0.7])
    got, want = expand(pose, np.zeros(3), depth), tree_from_rows(pose, rows, depth, 9)
    for a, b in zip(got[:3], want[:3]):                     # leaves, first poses, leaf velocities
        assert np.array_equal(a, b)
    assert len(got[3]) == depth                             # and every level, for the stage cost
    for (pa, va), (pb, vb) in zip(got[3], want[3]):
        assert np.array_equal(pa, pb) and np.array_equal(va, vb)


@pytest.mark.parametrize("response, words", [
    (_response(np.zeros((9, 6)), success=False, message="busy"), "refused: busy"),
    (_response(np.zeros((9, 6)), names=list("ABC")), "are not the library's"),
    (_response(np.zeros(50)), "not rows of 6"),
    (_response(np.zeros((10, 6))), "needs (9, 6)"),
    (_response(np.full((9, 6), np.nan)), "no finite leaf"),
])
def test_bad_responses_give_a_reason(response, words):
    expand, reason = RolloutClient.expander(response, NAMES, 1)
    assert expand is None and words in reason
