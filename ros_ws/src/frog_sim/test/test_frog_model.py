"""Frog model, actuation fit, schedules, rigid-body state and the public API."""
import numpy as np
import pytest

from frog_sim.core.actuation import ActuationLibrary, read_curvature_profiles
from frog_sim.core.frog_model import build_frog_model
from frog_sim.core.model_parameters import FrogParameters, parameter_table
from frog_sim.core.rigid_body import (center_of_mass, heading_angle, nodal_velocities,
                                      rigid_body_state, yaw_rate)
from frog_sim.core.rod_network import discrete_curvature
from frog_common.primitives import primitive_limbs, primitive_name
from frog_sim.core.schedules import ActivationSchedule
from frog_sim.core.simulation import FrogSimulation


@pytest.fixture(scope='module')
def library():
    return ActuationLibrary.load()


def test_frog_model_geometry_matches_paper():
    model = build_frog_model()
    net = model.network
    assert model.n_nodes == 128                                  # paper: N_total = 128
    assert np.allclose(net.edge_rest_length[net.edge_group == 0], 0.090 / 23)
    # joint nodes: 3 edges and 2 bending energies each (paper)
    for corner in model.corner_nodes.values():
        assert np.sum(net.edges == corner) == 3
        assert np.sum(net.bends[:, 1] == corner) == 2
    # limb mass grows with EGaIn
    m10 = build_frog_model(FrogParameters(egain_vol_pct=10)).mass
    m50 = build_frog_model(FrogParameters(egain_vol_pct=50)).mass
    limb = model.limb_nodes['FL']
    assert np.all(m50[limb] > m10[limb])
    body_only = np.setdiff1d(np.arange(92), list(model.corner_nodes.values()))
    assert np.allclose(m50[body_only], m10[body_only])
    # limbs in the reference pose have the requested relaxed curvature
    kappa = discrete_curvature(net.positions, net.bends, net.bend_length)
    for limb_name, bends in model.limb_bends.items():
        assert np.allclose(np.abs(kappa[bends]), 125.0)
    rows = parameter_table()
    assert all(len(r[3]) > 5 for r in rows)                       # every parameter has a source


def test_actuation_fit_reproduces_measured_profiles(library, measured_file):
    data = read_curvature_profiles(measured_file("limb_curvature_profiles.csv"))
    assert len(library.profiles) == len(data) == 48
    for key, (t, kappa) in data.items():
        prof = library.profiles[key]
        swing = kappa.max() - kappa.min()
        assert prof.rms_error < 0.06 * swing, key                 # RMS < 6 % of the stroke
        fitted = prof.curvature(t)
        assert np.sqrt(np.mean((fitted - kappa) ** 2)) == pytest.approx(prof.rms_error)
        assert abs(fitted.min() - kappa.min()) < 10.0             # actuated curvature [1/m]


def test_actuation_profile_lookup_errors_name_the_value(library):
    """Inside the measured hull a design is interpolated; outside it is refused."""
    p15 = library.profile(15, 1.0)
    assert {(e, f) for e, f, _ in p15.interpolated_from} <= {(10.0, 1.0), (20.0, 1.0), (10.0, 0.9), (20.0, 1.1),
                                                              (10.0, 1.1), (20.0, 0.9)}
    with pytest.raises(ValueError, match=r"EGaIn 10 % at 2.5 Hz is outside the measured designs .*0.4-1.2 Hz"):
        library.profile(10, 2.5)
    with pytest.raises(ValueError, match="outside the measured designs"):
        library.profile(60, 2.0)
    with pytest.raises(ValueError, match="EGaIn 15 % has no measured profile"):
        library.profile(15, 1.0, interpolate=False)
    with pytest.raises(ValueError, match="1.65 Hz was not measured"):
        library.profile(40, 1.65, interpolate=False)


def test_primitive_schedules():
    assert primitive_limbs('A') == (('FL', 'FR'), ())
    assert primitive_limbs(1) == (('FL', 'FR'), ('BL', 'BR'))
    assert primitive_limbs('C') == (('FL',), ('BL', 'BR'))        # 0111: FL, BL, BR
    assert primitive_limbs('I') == ((), ())
    assert primitive_name(8) == 'I'
    with pytest.raises(ValueError, match='12 is out of range 0-8'):
        primitive_name(12)
    with pytest.raises(ValueError, match='unknown'):
        primitive_name('Z')
    seq = ActivationSchedule.primitive_sequence(['D', 'A'], period=1.5, pulse=0.08)
    assert seq.times('FR').tolist() == [0.0, 1.5]                 # D = 1011 -> FR, BL, BR
    assert seq.times('FL').tolist() == [1.5]
    assert seq.times('BL').tolist() == [0.08]
    gait = ActivationSchedule.gait(0.5, 0.25, duration=4.0)
    assert gait.times('FR').tolist() == [0.0, 2.0]
    assert gait.times('BR').tolist() == [0.5, 2.5]
    with pytest.raises(ValueError, match='phase offset'):
        ActivationSchedule.gait(1.0, 1.2, 2.0)


def test_rigid_body_state_round_trip_eq13():
    model = build_frog_model()
    rng = np.random.default_rng(11)
    angle = 0.9
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    pos = model.reference_pose @ rot.T + np.array([0.2, -0.1])
    assert heading_angle(pos, model.reference_pose, model.mass) == pytest.approx(angle, abs=1e-12)
    assert heading_angle(model.reference_pose @ rot.T.T, model.reference_pose,
                         model.mass) == pytest.approx(-angle, abs=1e-12)   # signed
    assert np.allclose(center_of_mass(pos, model.mass), [0.2, -0.1], atol=1e-15)
    for _ in range(5):
        v_com = rng.uniform(-0.03, 0.03, 2)
        omega = rng.uniform(-0.5, 0.5)
        vel = nodal_velocities(pos, model.mass, v_com, omega)
        st = rigid_body_state(0.0, pos, vel, model.mass, model.reference_pose)
        assert np.allclose(st.com_velocity, v_com, atol=1e-15)
        assert st.yaw_rate == pytest.approx(omega, abs=1e-13)
    # a pure translation has no yaw rate
    assert yaw_rate(pos, np.tile([0.01, 0.02], (len(pos), 1)), model.mass) == pytest.approx(0, abs=1e-15)


def test_simulation_api_starts_from_given_body_velocity(library):
    sim = FrogSimulation(library=library)
    sim.set_pose(0.5, 0.2, np.pi / 2)
    sim.set_velocity(forward=0.03, lateral=-0.01, yaw_rate=0.3)
    st = sim.rigid_body_state()
    assert np.allclose(st.body_velocity, [0.03, -0.01], atol=1e-12)
    assert np.allclose(st.com_velocity, [0.01, 0.03], atol=1e-12)   # heading 90 deg
    assert st.yaw_rate == pytest.approx(0.3)
    assert st.heading == pytest.approx(np.pi / 2)
    sim.step(50)
    st2 = sim.rigid_body_state()
    assert st2.time == pytest.approx(50 * sim.time_step)
    assert 0 < st2.body_velocity[0] < 0.03                          # drag slows it down
    assert np.all(np.isfinite(sim.node_positions))


def test_pose_survives_choosing_a_gait(library):
    sim = FrogSimulation(library=library)
    sim.set_pose(1.0, 2.0, 0.5)
    sim.set_gait(0.8, 0.5)          # picks another profile (may rebuild the model at t = 0)
    st = sim.rigid_body_state()
    assert np.allclose(st.com, [1.0, 2.0]) and st.heading == pytest.approx(0.5)
    assert sim.profile.frequency_hz == 0.8


def test_reset_reproduces_a_fresh_run(library):
    def swim(sim):
        sim.set_gait(1.0, 0.5)
        sim.step(200)
        return sim.node_positions
    sim = FrogSimulation(library=library)
    sim.set_gait(1.0, 0.5)                  # builds the model for this profile
    sim.reset()
    first = swim(sim)
    sim.reset()
    assert sim.time == 0.0 and np.abs(sim.node_velocities).max() == 0.0
    assert np.array_equal(swim(sim), first)
    fresh = FrogSimulation(library=library)
    fresh.set_gait(1.0, 0.5)
    fresh.reset()
    assert np.array_equal(swim(fresh), first)


def test_primitive_fires_front_then_rear(library):
    sim = FrogSimulation(library=library)
    sim.execute_primitive('B')
    relaxed = sim.profile.relaxed_curvature
    sim.step(int(round(0.06 / sim.time_step)))
    k = sim.limb_curvatures
    assert k['FL'] < relaxed - 20 and k['FR'] < relaxed - 20       # front is actuating
    assert k['BL'] == pytest.approx(relaxed) and k['BR'] == pytest.approx(relaxed)
    sim.step(int(round(0.1 / sim.time_step)))
    assert sim.limb_curvatures['BL'] < relaxed - 20                 # rear fired after 80 ms
    with pytest.raises(ValueError, match='out of range 0-8'):
        sim.execute_primitive(9)


def test_symmetric_gait_swims_forward_without_turning(library):
    sim = FrogSimulation(library=library)
    sim.set_gait(1.0, 0.5)
    traj = sim.run(10.0, record_interval=0.05)                      # 10 cycles
    assert traj.com[-1, 0] > 0.02                                   # forward (+x)
    assert np.degrees(abs(traj.heading[-1] - traj.heading[0])) < 1.0
    assert abs(traj.com[-1, 1]) < 1e-3 * traj.com[-1, 0] + 1e-9


def test_every_parameter_has_a_range_or_choices_and_a_unit():
    """One table (dataclass metadata) for descriptors and validation."""
    from dataclasses import fields

    from frog_sim.core.model_parameters import parameter_range, parameter_specs, parameter_unit
    defaults = FrogParameters()
    specs = {s["name"]: s for s in parameter_specs()}
    assert set(specs) == {f.name for f in fields(FrogParameters)}
    for f in fields(FrogParameters):
        value = getattr(defaults, f.name)
        assert parameter_unit(f.name) == f.metadata["unit"]
        if isinstance(value, str):
            assert value in specs[f.name]["choices"] and parameter_range(f.name) is None
            continue
        lo, hi = parameter_range(f.name)
        assert lo < hi and lo <= value <= hi, f.name
        # just outside the range is refused with the name, the value and the range
        bad = hi * 1.5 + 1.0
        with pytest.raises(ValueError, match=rf"{f.name}=.* is above its maximum {hi!r}"):
            defaults.replace(**{f.name: type(value)(bad)})
    assert parameter_range("body_mass") == (0.02, 1.0) and parameter_unit("body_mass") == "kg"
    with pytest.raises(KeyError, match="did you mean 'body_mass'"):
        parameter_range("body_mas")


def test_interpolated_profiles_by_hand_and_leave_one_out(library, measured_file):
    """Deliver 5: linear (barycentric) interpolation of the eq. 9 coefficients."""
    # on a measured EGaIn line, half-way between two frequencies: the mean coefficients
    a, b = library.profiles[(40.0, 1.6)], library.profiles[(40.0, 1.7)]
    mid = library.profile(40, 1.65)
    assert mid.coefficients == pytest.approx(tuple(0.5 * (np.array(a.coefficients) + b.coefficients)))
    assert mid.switch_time == pytest.approx(0.5 * (a.switch_time + b.switch_time))
    assert mid.cycle_time == pytest.approx(1 / 1.65)
    # at a measured design the interpolation returns that design
    same = library.interpolated_profile(30, 1.2)
    assert same.coefficients == pytest.approx(library.profiles[(30.0, 1.2)].coefficients, abs=1e-9)
    # the built but unmeasured designs of experiment_speeds.csv can now be simulated
    for f in (1.5, 1.6, 1.7):
        assert library.profile(30, f).interpolated_from
    # leave-one-out against the measured curves: interior points of a measured EGaIn line
    from frog_sim.core.actuation import ActuationLibrary
    data = read_curvature_profiles(measured_file("limb_curvature_profiles.csv"))
    errors = []
    for (e, f), prof in library.profiles.items():
        freqs = library.frequencies(e)
        if f in (freqs[0], freqs[-1]):
            continue
        sub = ActuationLibrary({k: v for k, v in library.profiles.items() if k != (e, f)}, {})
        est = sub.interpolated_profile(e, f)
        t, kappa = data[(e, f)]
        rel = np.sqrt(np.mean((est.curvature(t) - kappa) ** 2)) / np.ptp(kappa)
        errors.append(rel)
        assert rel < 0.25, (e, f, rel)       # across EGaIn (a neighbour left out) up to ~21 %
    assert np.median(errors) < 0.03           # typically ~2.4 % of the stroke
