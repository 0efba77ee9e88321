"""The pose filter against analytic motion: velocities, unwrapping, outliers, dropouts."""
import numpy as np
import pytest

from frog_vision.core.state_filter import FilterSettings, PoseFilter, raw_differences

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
