"""Nearest-neighbour lookup against brute force, both metrics, k > 1, and loading with a period."""

import math

import numpy as np
import pytest

from frog_planner.core.transition_model import TransitionModel

RNG_SEED = 11


def _random_model_arrays(n_states=300, n_prim=9, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    init = np.column_stack([rng.uniform(0.0, 0.04, n_states), rng.uniform(-0.03, 0.03, n_states),
                            rng.uniform(-0.52, 0.52, n_states)])
    trans = rng.normal(0.0, 0.05, (n_prim, n_states, 6))
    trans[..., 2] = rng.uniform(-math.pi, math.pi, (n_prim, n_states))
    return init, trans


def _queries(n=60, seed=5):
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-0.005, 0.045, n), rng.uniform(-0.035, 0.035, n), rng.uniform(-0.6, 0.6, n)])
    q[0] = [0.0, 0.0, 0.0]          # at rest: the relative metric's denominators are all guarded
    q[1] = [0.02, 0.0, 1e-9]        # one near-zero component
    return q


def _brute_force(init, query, metric, k, scale, floor_fraction=0.05):
    """k nearest by explicit loops over the states (Algorithm 1 step 6 for 'relative')."""
    dists = []
    for i, state in enumerate(init):
        total = 0.0
        for c in range(3):
            if metric == "euclidean":
                denom = scale[c]
            else:
                denom = max(abs(query[c]), floor_fraction * scale[c])
            total += ((query[c] - state[c]) / denom) ** 2
        dists.append((math.sqrt(total), i))
    dists.sort()
    return [i for _, i in dists[:k]], [d for d, _ in dists[:k]]


@pytest.mark.parametrize("metric", ["euclidean", "relative"])
@pytest.mark.parametrize("k", [1, 4])
def test_nearest_matches_brute_force(metric, k):
    init, trans = _random_model_arrays()
    model = TransitionModel(init, trans, list("ABCDEFGHI"), metric=metric, k=k)
    scale = [np.ptp(init[:, c]) for c in range(3)]
    queries = _queries()
    idx, dist = model.nearest(queries)
    assert idx.shape == (len(queries), k)
    for q, got_idx, got_dist in zip(queries, idx, dist):
        want_idx, want_dist = _brute_force(init, q, metric, k, scale)
        assert list(got_idx) == want_idx
        np.testing.assert_allclose(got_dist, want_dist, rtol=1e-9)
        assert np.all(np.isfinite(got_dist))


def test_relative_metric_is_algorithm1_step6_away_from_the_guard():
    init, trans = _random_model_arrays(50)
    model = TransitionModel(init, trans, list("ABCDEFGHI"), metric="relative")
    q = np.array([0.03, -0.02, 0.4])    # every component well above its floor
    d_paper = np.linalg.norm((q - init) / q, axis=1)
    assert model.nearest(q)[0][0, 0] == int(np.argmin(d_paper))


def test_lookup_returns_the_neighbours_transitions_and_averages_k():
    init, trans = _random_model_arrays()
    q = _queries(5)
    one = TransitionModel(init, trans, list("ABCDEFGHI"), k=1)
    got = one.lookup(q)
    assert got.shape == (5, 9, 6)
    scale = [np.ptp(init[:, c]) for c in range(3)]
    for m in range(5):
        (n,), _ = _brute_force(init, q[m], "euclidean", 1, scale)
        np.testing.assert_array_equal(got[m], trans[:, n, :])
    three = TransitionModel(init, trans, list("ABCDEFGHI"), k=3)
    got = three.lookup(q)
    for m in range(5):
        ns, _ = _brute_force(init, q[m], "euclidean", 3, scale)
        for p in range(9):
            rows = trans[p, ns, :]
            np.testing.assert_allclose(got[m, p, [0, 1, 3, 4, 5]], rows[:, [0, 1, 3, 4, 5]].mean(axis=0))
            sin_mean, cos_mean = np.sin(rows[:, 2]).sum(), np.cos(rows[:, 2]).sum()
            assert got[m, p, 2] == pytest.approx(math.atan2(sin_mean, cos_mean))


def test_averaging_headings_across_pi_stays_near_pi():
    init = np.array([[0.01, 0.0, 0.0], [0.011, 0.0, 0.0], [0.03, 0.0, 0.3]])
    trans = np.zeros((1, 3, 6))
    trans[0, :, 2] = [3.1, -3.1, 0.0]
    model = TransitionModel(init, trans, ["A"], k=2)
    heading = model.lookup([0.0105, 0.0, 0.0])[0, 0, 2]
    assert abs(abs(heading) - math.pi) < 1e-9          # not 0, the naive mean


def test_failed_simulations_drop_their_initial_state():
    init, trans = _random_model_arrays(20)
    target = init[7].copy()
    trans[3, 7, :] = np.nan
    model = TransitionModel(init, trans, list("ABCDEFGHI"))
    assert model.n_states == 19 and model.dropped_states == 1
    idx, _ = model.nearest(target)
    assert not np.allclose(model.initial_states[idx[0, 0]], target)
    assert np.all(np.isfinite(model.lookup(target)))


@pytest.mark.parametrize("kwargs, words", [({"metric": "manhattan"}, "metric 'manhattan' is unknown"),
                                           ({"k": 0}, "k 0 is out of range"), ({"k": 301}, "k 301 is out of range"),
                                           ({"scale": [1.0, 0.0, 1.0]}, "scale")])
def test_bad_settings_are_rejected(kwargs, words):
    init, trans = _random_model_arrays()
    with pytest.raises(ValueError, match=words):
        TransitionModel(init, trans, list("ABCDEFGHI"), **kwargs)


def test_load_selects_the_period_in_si_units(tmp_path, synthetic):
    arrays = synthetic.library_arrays(n_states=30, horizon=3.0, sample_interval=0.05)
    path = synthetic.write_library(tmp_path / "lib.npz", arrays)
    for period, index in [(1.5, 30), (0.75, 15), (3.0, 60)]:
        model = TransitionModel.load(path, period=period)
        assert model.period == period
        np.testing.assert_array_equal(model.transitions, arrays["transitions"][:, :, index, :].astype(float))
        np.testing.assert_array_equal(model.initial_states, arrays["initial_states"])
    # Yaw rates are rad/s throughout: the kinematic library's primitive C turns at 0.35 rad/s.
    model = TransitionModel.load(path, period=3.0)
    assert np.all(np.abs(model.transitions[:, :, 5]) < 0.6)
    assert model.primitive_names == list("ABCDEFGHI")
    assert model.primitive_id("C") == 2
    with pytest.raises(ValueError, match="primitive 'Z' is unknown"):
        model.primitive_id("Z")
    # off the sample grid: the two nearest samples interpolated (library_file tests check the accuracy)
    between = TransitionModel.load(path, period=1.52).transitions
    np.testing.assert_allclose(between, 0.6 * arrays["transitions"][:, :, 30] + 0.4 * arrays["transitions"][:, :, 31],
                               rtol=1e-6, atol=1e-9)   # the file stores float32
    with pytest.raises(ValueError, match="beyond the library horizon"):
        TransitionModel.load(path, period=3.2)


@pytest.mark.parametrize("max_ball", [0.0, math.inf])
@pytest.mark.parametrize("k", [1, 3])
def test_relative_metric_pruned_and_full_searches_both_match_brute_force(monkeypatch, max_ball, k):
    from frog_planner.core import transition_model
    monkeypatch.setattr(transition_model, "_RELATIVE_MAX_BALL", max_ball)   # 0: all full, inf: all pruned
    init, trans = _random_model_arrays(500, seed=2)
    model = TransitionModel(init, trans, list("ABCDEFGHI"), metric="relative", k=k)
    scale = [np.ptp(init[:, c]) for c in range(3)]
    queries = _queries(40, seed=9)
    idx, dist = model.nearest(queries)
    for q, got_idx, got_dist in zip(queries, idx, dist):
        want_idx, want_dist = _brute_force(init, q, "relative", k, scale)
        assert list(got_idx) == want_idx
        np.testing.assert_allclose(got_dist, want_dist, rtol=1e-9)


def test_states_marked_not_converged_are_dropped_when_loading(tmp_path, synthetic):
    arrays = synthetic.library_arrays(n_states=10, horizon=1.5, sample_interval=0.5)
    arrays["converged"][6, 4] = False          # row left finite: the flag alone must drop state 4
    model = TransitionModel.load(synthetic.write_library(tmp_path / "lib.npz", arrays), period=1.5)
    assert model.n_states == 9 and model.dropped_states == 1
    assert not np.any(np.all(model.initial_states == arrays["initial_states"][4], axis=1))


def test_gradient_correction_recovers_a_linear_library_exactly():
    """Transitions that are exactly affine in the initial state: the corrected lookup equals
    the affine function at the query (not at the nearest state), for k = 1 and k = 3."""
    rng = np.random.default_rng(4)
    states = rng.uniform([0.0, -0.03, -0.5], [0.04, 0.03, 0.5], size=(60, 3))
    slopes = rng.normal(size=(9, 3, 6))
    offsets = rng.normal(size=(9, 6)) * 0.01
    table = np.einsum("nc,pco->pno", states, slopes) + offsets[:, None, :]
    queries = rng.uniform([0.0, -0.03, -0.5], [0.04, 0.03, 0.5], size=(5, 3))
    truth = np.einsum("mc,pco->mpo", queries, slopes) + offsets[None]
    for k in (1, 3):
        model = TransitionModel(states, table * [1, 1, 0.01, 1, 1, 1], list("ABCDEFGHI"), k=k,
                                gradient_correction=True)
        got = model.lookup(queries)
        np.testing.assert_allclose(got, truth * [1, 1, 0.01, 1, 1, 1], atol=1e-9)
    plain = TransitionModel(states, table, list("ABCDEFGHI"))
    nearest = plain.nearest(queries)[0][:, 0]
    np.testing.assert_array_equal(plain.lookup(queries), table[:, nearest].transpose(1, 0, 2))
    with pytest.raises(ValueError, match="at least 4"):
        TransitionModel(states[:3], table[:, :3], list("ABCDEFGHI"), gradient_correction=True)


@pytest.mark.parametrize("metric", ["relative", "euclidean"])
def test_authors_lookup_searches_their_library_columns_and_returns_the_states_own_transitions(metric):
    """lookup authors_code: the neighbour is the brute-force nearest of the mapped states
    (x right = -left, y forward, deg/s), written out by hand here, and its transitions are the
    real state's."""
    init, trans = _random_model_arrays()
    mapped = np.column_stack([-init[:, 1], init[:, 0], np.degrees(init[:, 2])])
    m = TransitionModel(init, trans, list("ABCDEFGHI"), metric=metric, lookup="authors_code")
    scale = np.ptp(mapped, axis=0)
    q = _queries()
    idx, _ = m.nearest(q)
    for i, query in enumerate(q):
        assert idx[i, 0] == _brute_force(mapped, query, metric, 1, scale)[0]
    assert np.array_equal(m.lookup(q)[:, 3], trans[3, idx[:, 0]])
    # a robot swimming forward at 25 mm/s without turning is matched, as in their code, with the
    # state that slides to the right at 25 mm/s (their xdot0) with no forward speed and no turn
    states = np.array([[0.025, 0.0, 0.0], [0.0, -0.025, 0.0], [0.0, 0.0, 0.2]])
    m3 = TransitionModel(states, trans[:, :3], list("ABCDEFGHI"), metric="relative", lookup="authors_code")
    assert m3.nearest([0.025, 0.0, 0.0])[0][0, 0] == 1
    assert TransitionModel(states, trans[:, :3], list("ABCDEFGHI"), metric="relative").nearest(
        [0.025, 0.0, 0.0])[0][0, 0] == 0
    with pytest.raises(ValueError, match="lookup"):
        TransitionModel(init, trans, list("ABCDEFGHI"), lookup="deg")
