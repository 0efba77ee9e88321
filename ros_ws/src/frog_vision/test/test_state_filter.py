"""The pose filter against analytic motion: velocities, unwrapping, outliers, dropouts."""
import numpy as np
import pytest

from frog_vision.core.frame_difference import raw_differences
from frog_vision.core.state_filter import FilterSettings, PoseFilter

R = np.diag([2e-4 ** 2, 2e-4 ** 2, np.radians(0.1) ** 2])


def _circle(t, v=0.03, w=np.radians(20)):
    """Constant body twist: a circle (exact)."""
    th = 0.3 + w * t
    x = v / w * (np.sin(th) - np.sin(0.3))
    y = -v / w * (np.cos(th) - np.cos(0.3))
    return np.column_stack([x, y, th])


def test_constant_twist_is_recovered_and_beats_raw_differences(rng):
    t = np.arange(0, 20, 1 / 30)
    truth = _circle(t)
    meas = truth + rng.normal(0, 1, truth.shape) * np.sqrt(np.diag(R))
    meas[:, 2] = np.angle(np.exp(1j * meas[:, 2]))          # as a detector reports it: wrapped
    # smooth motion: a process noise matched to it (the default is tuned for kicks)
    f = PoseFilter(FilterSettings(accel_noise=1e-5, yaw_accel_noise=1e-3))
    out = np.array([f.update(ti, zi, R)[0].body_velocity for ti, zi in zip(t, meas)])
    heading = f.state(t[-1]).pose[2]
    assert heading == pytest.approx(truth[-1, 2], abs=0.01)   # unwrapped over > 2 pi
    late = t > 3
    assert np.allclose(out[late].mean(axis=0), [0.03, 0, np.radians(20)], atol=[5e-4, 5e-4, 0.01])
    raw = raw_differences(t, meas)
    err_f = np.sqrt(np.mean((out[late, 0] - 0.03) ** 2))
    err_r = np.sqrt(np.mean((raw[late, 0] - 0.03) ** 2))
    assert err_r / err_f > 5


def test_outlier_is_rejected_and_a_real_jump_is_followed(rng):
    f = PoseFilter()
    for k in range(60):
        f.update(k / 30, np.array([0.01 * k / 30, 0, 0]), R)
    st, why = f.update(60 / 30, np.array([0.1, 0.1, 1.0]), R)       # a wrong quad
    assert "outlier" in why and st.pose[0] == pytest.approx(0.02, abs=1e-3)
    st, why = f.update(61 / 30, np.array([0.01 * 61 / 30, 0, 0]), R)
    assert why is None
    # the robot was really moved (picked up): three consistent measurements restart the filter
    for k in range(62, 66):
        st, why = f.update(k / 30, np.array([0.3, -0.2, 2.0]), R)
    assert st.pose[0] == pytest.approx(0.3) and st.pose[1] == pytest.approx(-0.2)


def test_coasting_and_reset_after_long_dropouts():
    s = FilterSettings(coast_timeout=0.5, reset_timeout=1.0)
    f = PoseFilter(s)
    for k in range(60):
        f.update(k / 30, np.array([0.02 * k / 30, 0, 0]), R)
    coast = f.state(2.3)
    assert coast is not None and coast.coasting
    assert coast.pose[0] == pytest.approx(0.02 * 2.3, abs=1e-3)      # predicted at 2 cm/s
    assert f.state(2.6) is None                                       # lost: publish nothing
    st, _ = f.update(3.5, np.array([0.5, 0.5, 0.0]), R)               # after the reset timeout
    assert f.n_resets == 1 and np.allclose(st.body_velocity, 0)


def test_stale_and_bad_measurements():
    f = PoseFilter()
    f.update(1.0, np.zeros(3), R)
    st, why = f.update(0.5, np.zeros(3), R)
    assert "older" in why
    with pytest.raises(ValueError, match="not finite"):
        f.update(2.0, np.array([np.nan, 0, 0]), R)
    with pytest.raises(ValueError, match="reset_timeout"):
        FilterSettings(coast_timeout=2.0, reset_timeout=1.0)


def _kicked(rng, period=1.5, n_kicks=6, fps=30.0):
    """Impulsive swimming: every ``period`` a 0.15 s stroke adds 15 mm/s and 15 deg/s (alternating
    turn direction), then the twist decays by drag (8 s / 5 s), integrated finely; noisy poses."""
    dt = 1e-3
    kicks = 0.2 + period * np.arange(n_kicks)
    t = np.arange(0, kicks[-1] + period, dt)
    tw = np.zeros((len(t), 3))
    pose = np.zeros((len(t), 3))
    for i in range(1, len(t)):
        acc = -tw[i - 1] / np.array([8.0, 8.0, 5.0])
        for j, k in enumerate(kicks):
            if k <= t[i] < k + 0.15:
                acc = acc + np.array([0.015, 0.0, np.radians(15) * (-1) ** j]) / 0.15
        tw[i] = tw[i - 1] + acc * dt
        th = pose[i - 1, 2]
        pose[i] = pose[i - 1] + dt * np.array([np.cos(th) * tw[i, 0], np.sin(th) * tw[i, 0], tw[i, 2]])
    frames = np.arange(0, len(t), int(round(1 / (fps * dt))))
    meas = pose[frames] + rng.normal(0, 1, (len(frames), 3)) * np.sqrt(np.diag(R))
    return t[frames], meas, tw[frames], kicks


def _run(t, meas, kicks, settings=None):
    f = PoseFilter(settings)
    pending = list(kicks)
    out = []
    for ti, zi in zip(t, meas):
        while pending and pending[0] <= ti:
            f.kick(pending.pop(0))
        out.append(f.update(ti, zi, R)[0].body_velocity)
    return np.array(out)


def test_kick_inputs_follow_the_strokes_and_smooth_the_coasting(rng):
    t, meas, tw, kicks = _kicked(rng)
    late = t > 1.0
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    with_kicks = _run(t, meas, kicks)
    without = _run(t, meas, [])
    raw = raw_differences(t, meas)
    v = [rms(np.linalg.norm(e[late, :2] - tw[late, :2], axis=1)) for e in (with_kicks, without, raw)]
    w = [rms(e[late, 2] - tw[late, 2]) for e in (with_kicks, without, raw)]
    # measured (seeded), with kicks / without / raw differences: velocity 2.09 / 2.76 / 11.6 mm/s,
    # yaw rate 1.47 / 1.89 / 4.26 deg/s
    assert v[0] < 0.85 * v[1] and w[0] < 0.85 * w[1], (v, w)
    assert v[2] / v[0] > 5 and w[2] / w[0] > 2.5, (v, w)


def test_without_kicks_the_filter_is_unchanged_and_kicks_are_causal(rng):
    t, meas, _, kicks = _kicked(rng, n_kicks=2)
    # no kick: the constant-twist filter of accel_noise / yaw_accel_noise, whatever the kick settings
    a = _run(t, meas, [], FilterSettings(kick_accel_noise=1.0, coast_accel_noise=1e-9, coast_drag_time=0.5))
    b = _run(t, meas, [], FilterSettings())
    assert np.array_equal(a, b)
    # a kick changes only the predictions after its stamp: before it the filter coasts (drag)
    f = PoseFilter()
    f.update(0.0, np.zeros(3), R)
    f.update(1 / 30, np.array([0.001, 0, 0]), R)
    f.kick(0.5)
    q_before, r_before = f._process_model(0.1, 0.2)
    q_in, r_in = f._process_model(0.5, 0.6)
    assert np.allclose(q_before, [3e-6, 3e-6, 1e-3]) and np.all(r_before > 0)
    assert np.allclose(q_in, [1e-4, 1e-4, 1.0]) and np.all(r_in == 0)
    q_half, _ = f._process_model(0.65, 0.75)                      # half inside the 0.2 s window
    assert np.allclose(q_half, 0.5 * (q_before + q_in))
    with pytest.raises(ValueError, match="not finite"):
        f.kick(float("nan"))
    # kick_delay shifts the window
    f.settings = FilterSettings(kick_delay=0.1)
    assert np.allclose(f._process_model(0.5, 0.6)[0], q_before)
    assert np.allclose(f._process_model(0.6, 0.8)[0], q_in)
    with pytest.raises(ValueError, match="kick_delay"):
        FilterSettings(kick_delay=-0.1)


def test_frame_difference_estimator_gives_the_raw_differences_and_their_noise(rng):
    """The authors' estimate: the measured pose itself, the twist of consecutive frames (a
    straight run: analytic), and the twist covariance of two independent frames."""
    from frog_vision.core.frame_difference import FrameDifferenceEstimator
    t = np.arange(0, 20, 1 / 14)
    truth = _circle(t)
    meas = truth + rng.normal(0, 1, truth.shape) * np.sqrt(np.diag(R))
    meas[:, 2] = np.angle(np.exp(1j * meas[:, 2]))
    e = FrameDifferenceEstimator()
    states = [e.update(ti, zi, R)[0] for ti, zi in zip(t, meas)]
    assert np.allclose(states[0].body_velocity, 0)
    assert states[-1].pose[2] == pytest.approx(truth[-1, 2], abs=0.01)       # unwrapped
    out = np.array([s.body_velocity for s in states[1:]])
    raw = raw_differences(t, meas)[1:]
    assert np.allclose(out, raw, atol=1e-12)
    # the yaw-rate scatter is the one of two independent frames: sqrt(2) sigma / dt
    sd_pred = np.sqrt(2 * R[2, 2]) * 14
    assert np.std(out[:, 2] - np.radians(20)) == pytest.approx(sd_pred, rel=0.15)
    assert states[-1].twist_covariance[2, 2] == pytest.approx(sd_pred ** 2, rel=1e-6)
    # a straight line at 2 cm/s along 30 deg: the forward speed exactly, no lateral
    e = FrameDifferenceEstimator()
    th = np.radians(30)
    for k in range(5):
        s, why = e.update(k * 0.07, np.array([0.02 * k * 0.07 * np.cos(th), 0.02 * k * 0.07 * np.sin(th), th]), R)
    assert why is None and s.body_velocity == pytest.approx([0.02, 0, 0], abs=1e-12)


def test_frame_difference_estimator_holds_then_forgets_and_refuses_old_frames():
    from frog_vision.core.frame_difference import FrameDifferenceEstimator
    st = FilterSettings(coast_timeout=0.5, reset_timeout=1.0)
    e = FrameDifferenceEstimator(st)
    e.update(0.0, np.zeros(3), R)
    e.update(0.1, np.array([0.003, 0, 0.01]), R)
    held = e.state(0.4)
    assert held.coasting and held.pose == pytest.approx([0.003, 0, 0.01]) and held.body_velocity[0] == \
        pytest.approx(0.03 * np.cos(0.01))                                  # rotated into the new heading
    assert e.state(0.7) is None                                              # past the coast timeout
    s, why = e.update(0.05, np.zeros(3), R)
    assert why is not None and "not newer" in why and s.pose[0] == pytest.approx(0.003)
    s, why = e.update(2.0, np.array([0.1, 0.1, 0.2]), R)                    # after reset_timeout
    assert why is None and np.allclose(s.body_velocity, 0) and e.n_resets == 1
    with pytest.raises(ValueError, match="not finite"):
        e.update(2.1, np.array([np.nan, 0, 0]), R)
