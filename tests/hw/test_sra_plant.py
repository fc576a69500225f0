"""Simulated pneumatic soft arm (inflarm_hw.sra_plant), no ROS."""

import dataclasses

import numpy as np
import pytest

from inflarm_hw.sra_plant import IDEAL, NOISE_FREE, SoftArmPlant, SoftArmPlantParams
from inflarm_hw.valve import ITV2050, pressure_to_voltage
from inflarm_model.camera import sphere_position_std
from inflarm_model.soft_arm import CHAMBERS, quadrant_of

PEA, B1, B2, B3, B4 = (CHAMBERS.index(c) for c in CHAMBERS)


def _hold(plant, command, seconds, dt=0.2):
    for _ in range(int(round(seconds / dt))):
        plant.step(command, dt)


def _command(**kpa):
    c = np.zeros(5)
    for name, value in kpa.items():
        c[CHAMBERS.index(name)] = value * 1e3
    return c


def test_rest_is_straight_at_the_fig7_start():
    plant = SoftArmPlant(3)
    np.testing.assert_allclose(plant.end_point, np.tile([0.0, 0.0, 0.604], (3, 1)))
    np.testing.assert_allclose(plant.chamber_pressures, 0.0)
    _hold(plant, np.zeros(5), 5.0)
    np.testing.assert_allclose(plant.end_point, np.tile([0.0, 0.0, 0.604], (3, 1)), atol=1e-12)


def test_the_plant_valves_are_eq2_of_inflarm_hw_valve():
    plant = SoftArmPlant()
    valve = plant.params.valve
    assert valve == ITV2050
    pressures = np.array([4e3, 20e3, 450e3, 895e3])
    np.testing.assert_allclose(plant.valve_voltage(pressures), pressure_to_voltage(pressures))
    np.testing.assert_allclose(plant.valve_pressure(plant.valve_voltage(pressures)), pressures)
    np.testing.assert_allclose(plant.valve_pressure(valve.voltage_max), valve.full_scale)


def test_valve_dead_zone_and_range():
    plant = SoftArmPlant()
    v = plant.valve_voltage([3.9e3, 2e6, -5e3])
    np.testing.assert_allclose(plant.valve_pressure(v), [0.0, 895e3, 0.0])


def test_stepping_with_voltages_equals_stepping_with_their_set_pressures():
    by_pressure, by_voltage = SoftArmPlant(), SoftArmPlant()
    command = _command(PEA=20, B3=30, B4=3.9)
    for _ in range(10):
        by_pressure.step(command, 0.1)
        by_voltage.step_valve_voltages(pressure_to_voltage(command), 0.1)
    np.testing.assert_array_equal(by_voltage.chamber_pressures, by_pressure.chamber_pressures)
    assert by_pressure.chamber_pressures[0, B4] == 0.0  # dead zone
    with pytest.raises(ValueError, match='finite voltages'):
        by_voltage.step_valve_voltages(np.full(5, np.nan), 0.1)


def test_commands_in_the_dead_zone_leave_the_arm_at_rest():
    plant = SoftArmPlant()
    _hold(plant, _command(PEA=3.9, B1=3.9, B2=3.9, B3=3.9, B4=3.9), 10.0)
    np.testing.assert_allclose(plant.chamber_pressures, 0.0)
    np.testing.assert_allclose(plant.end_point, [[0.0, 0.0, 0.604]])


def _reachable_points(rng, n):
    """Points whose holding pressures are all outside the valves' dead zone."""
    points = rng.uniform([0.04, 0.04, 0.64], [0.12, 0.12, 0.85], (n, 3))
    points[:, :2] *= rng.choice([-1.0, 1.0], (n, 2))
    return points


def test_holding_pressures_invert_the_static_map():
    rng = np.random.default_rng(7)
    points = _reachable_points(rng, 50)
    plant = SoftArmPlant(50)
    pressures = plant.holding_pressures(points)
    np.testing.assert_allclose(plant.static_end_point(pressures), points, atol=1e-12)
    # only the two bellows of the target's quadrant are inflated (Fig 4)
    active = pressures[:, 1:] > 0.0
    assert np.all(active.sum(axis=1) <= 2)
    q1 = quadrant_of(points[:, 0], points[:, 1]) == 1
    assert not np.any(active[q1][:, [B1 - 1, B2 - 1]])


def test_holding_pressures_below_the_dead_zone_cannot_be_held():
    plant = SoftArmPlant()
    point = [0.004, 0.10, 0.75]  # needs ~3 kPa in B4
    pressures = plant.holding_pressures(point)
    assert 0.0 < pressures[0, B4] < plant.params.valve.dead_zone
    plant.reset(end_point=point)
    _hold(plant, pressures, 15.0)  # the valve exhausts it (the wall's creep trails the gas)
    assert plant.chamber_pressures[0, B4] < 1.0
    assert plant.end_point[0, 0] < 0.0015


def test_reset_holds_the_requested_point():
    rng = np.random.default_rng(7)
    points = _reachable_points(rng, 8)
    plant = SoftArmPlant(8)
    plant.reset(end_point=points)
    np.testing.assert_allclose(plant.end_point, points, atol=1e-12)
    before = plant.end_point
    _hold(plant, plant.chamber_pressures, 5.0)
    np.testing.assert_allclose(plant.end_point, before, atol=1e-9)


def test_constant_pressures_settle_near_the_static_point():
    rng = np.random.default_rng(7)
    points = _reachable_points(rng, 20)
    plant = SoftArmPlant(20)
    pressures = plant.holding_pressures(points)
    _hold(plant, pressures, 20.0)
    # within the hysteresis band: the play on both PEAs in z, the bellows' play (as tilt)
    # times the arm's length laterally
    p = plant.params
    error = np.abs(plant.end_point - points)
    assert np.all(error[:, 2] <= 2 * p.pea_play * p.pea_rest_length + 0.5e-3)
    assert np.all(error[:, :2] <= 0.7 * p.bellows_play + 0.5e-3)


@pytest.mark.parametrize(('pair', 'quadrant'), [
    (('B3', 'B4'), 1), (('B2', 'B3'), 2), (('B1', 'B2'), 3), (('B1', 'B4'), 4)])
def test_bellows_pairs_bend_into_the_fig4_quadrant(pair, quadrant):
    plant = SoftArmPlant()
    _hold(plant, _command(PEA=20, **{pair[0]: 20, pair[1]: 20}), 5.0)
    x, y, _ = plant.end_point[0]
    assert min(abs(x), abs(y)) > 0.03
    assert quadrant_of(x, y) == quadrant


@pytest.mark.parametrize(('bellows', 'direction'), [
    ('B1', (0, -1)), ('B2', (-1, 0)), ('B3', (0, 1)), ('B4', (1, 0))])
def test_each_bellows_pushes_away_from_its_side(bellows, direction):
    plant = SoftArmPlant()
    _hold(plant, _command(**{bellows: 25}), 5.0)
    lateral = plant.end_point[0, :2]
    cos = lateral @ np.asarray(direction, dtype=float) / np.linalg.norm(lateral)
    assert cos > np.cos(np.radians(5.0))


def test_bending_lowers_z():
    plant = SoftArmPlant(2)
    command = np.array([_command(PEA=20), _command(PEA=20, B3=30, B4=30)])
    _hold(plant, command, 10.0)
    straight, bent = plant.end_point
    assert bent[2] < straight[2] - 0.01


def _time_to_63_percent(chamber):
    plant = SoftArmPlant()
    command = np.zeros(5)
    command[chamber] = 20e3
    for k in range(1, 101):
        plant.step(command, 0.05)
        if plant.chamber_pressures[0, chamber] >= (1 - np.exp(-1)) * 20e3:
            return k * 0.05
    return np.inf


def test_pea_chamber_is_slow_and_bellows_fast():
    t_pea = _time_to_63_percent(PEA)
    t_bellows = _time_to_63_percent(B3)
    # pneumatic time constant growing with the volume, plus the walls' creep and the gas's
    # expansion as they stretch
    assert 1.4 <= t_pea <= 2.0
    assert 0.8 <= t_bellows <= 1.3
    assert t_pea > 1.4 * t_bellows


def test_result_does_not_depend_on_the_step_size():
    coarse, fine = SoftArmPlant(), SoftArmPlant()
    command = _command(PEA=15, B2=25, B3=10)
    coarse.step(command, 0.2)
    for _ in range(4):
        fine.step(command, 0.05)
    np.testing.assert_allclose(coarse.end_point, fine.end_point, atol=1e-12)
    np.testing.assert_allclose(coarse.chamber_pressures, fine.chamber_pressures, rtol=1e-12)


def test_valves_deliver_a_command_valve_delay_after_it():
    plant = SoftArmPlant(1, NOISE_FREE)
    assert plant.params.valve_delay == 0.1  # the documented default
    command = _command(PEA=20, B3=30)
    outputs, pressures = [], []
    for _ in range(10):  # t = 0.02 ... 0.2 s
        plant.step(command, 0.02)
        outputs.append(plant.valve_outputs[0])
        pressures.append(plant.chamber_pressures[0])
    np.testing.assert_array_equal(outputs[3], 0.0)  # t = 0.08 s
    np.testing.assert_array_equal(pressures[4], 0.0)  # t = 0.1 s: nothing has flowed yet
    np.testing.assert_allclose(outputs[5], command)  # t = 0.12 s
    assert pressures[5][PEA] > 0.0 and pressures[5][B3] > 0.0


def test_commands_in_flight_arrive_in_order():
    plant = SoftArmPlant(1, NOISE_FREE)
    first, second = _command(B4=10), _command(B4=30)
    plant.step(first, 0.05)
    plant.step(second, 0.05)
    plant.step(second, 0.05)  # t = 0.15 s: the first command left the valves at 0.1 s
    np.testing.assert_allclose(plant.valve_outputs[0], first)
    plant.step(second, 0.05)
    np.testing.assert_allclose(plant.valve_outputs[0], second)


def test_a_step_longer_than_the_delay_is_the_ideal_response_shifted_by_it():
    delayed, ideal = SoftArmPlant(1, NOISE_FREE), SoftArmPlant(1, IDEAL)
    command = _command(PEA=15, B2=25, B3=10)
    delayed.step(command, 0.2)
    delayed.step(command, 0.2)
    ideal.step(np.zeros(5), 0.1)
    ideal.step(command, 0.3)
    np.testing.assert_allclose(delayed.end_point, ideal.end_point, rtol=1e-12)
    np.testing.assert_allclose(delayed.chamber_pressures, ideal.chamber_pressures, rtol=1e-12)


def test_reset_to_a_point_has_the_valves_holding_it():
    plant = SoftArmPlant(1, NOISE_FREE)
    target = np.array([0.1, 0.11, 0.67])
    plant.reset(end_point=target)
    hold = plant.holding_pressures(target)[0]
    np.testing.assert_allclose(plant.valve_outputs[0], hold)
    _hold(plant, hold, 2.0, dt=0.02)  # no dip while the first command is in flight
    np.testing.assert_allclose(plant.end_point[0], target, atol=1e-9)


def test_long_steps_stay_stable():
    plant = SoftArmPlant()
    for _ in range(20):
        plant.step(_command(PEA=100, B4=100), 2.0)
    assert np.all(np.isfinite(plant.end_point))
    assert plant.end_point[0, 2] < 1.0
    # the bellows' wall still creeps after 40 s at full stretch: its gas trails by ~60 Pa
    np.testing.assert_allclose(plant.chamber_pressures[0, [PEA, B4]], 100e3, rtol=1e-3)


def test_hysteresis_separates_rising_and_falling_branches():
    rising, falling = SoftArmPlant(), SoftArmPlant()
    _hold(rising, _command(PEA=15), 20.0)
    _hold(falling, _command(PEA=40), 20.0)
    _hold(falling, _command(PEA=15), 20.0)
    gap = falling.end_point[0, 2] - rising.end_point[0, 2]
    play = rising.params.pea_play * rising.params.pea_rest_length  # [m] per PEA
    # the PEA pair doubles the axial play: the branches are 2 x 2 x play apart in z
    assert 2.0 * play < gap <= 4.0 * play + 2e-5  # + the creep left after 20 s


def test_arms_are_independent_and_match_single_arm_runs():
    rng = np.random.default_rng(7)
    commands = rng.uniform(0.0, 40e3, (4, 5))
    batch = SoftArmPlant(4)
    _hold(batch, commands, 3.0)
    for i in range(4):
        single = SoftArmPlant(1)
        _hold(single, commands[i:i + 1], 3.0)
        np.testing.assert_allclose(batch.end_point[i], single.end_point[0], rtol=1e-12)


def test_measurement_noise_follows_the_camera_geometry():
    """Noise across the camera's line of sight from the image centre's error, larger noise
    along it from the image radius' error (`sphere_position_std`), at the camera's distance."""
    plant = SoftArmPlant(20000, rng=np.random.default_rng(7))
    p = plant.params
    assert (p.noise_center_px, p.noise_radius_px) == (0.12, 0.013)  # the documented defaults
    error = plant.measure() - plant.end_point
    ray = plant.end_point[0] - np.asarray(p.camera.translation_m)
    distance = np.linalg.norm(ray)
    ray /= distance
    lateral, depth = sphere_position_std(distance, 0.5 * p.camera.ball_diameter_m,
                                         p.camera.focal_px, 0.12, 0.013)
    along = error @ ray
    across = error - along[:, None] * ray
    np.testing.assert_allclose(along.std(), depth, rtol=0.03)
    np.testing.assert_allclose(np.sqrt((across ** 2).sum(axis=1).mean() / 2.0), lateral,
                               rtol=0.03)
    assert depth > 5.0 * lateral
    # the camera (0, -1.1, 0.78) looks along +y: the straight arm's y is the noisy axis, its
    # median error within sra_sim's camera + tracker's (0.73 mm in depth, 1.1-1.2 m away)
    assert 0.5e-3 < np.median(np.abs(error[:, 1])) < 0.8e-3
    np.testing.assert_allclose(error.mean(axis=0), 0.0, atol=3e-5)
    exact = SoftArmPlant(2, NOISE_FREE)
    np.testing.assert_array_equal(exact.measure(), exact.end_point)


@pytest.mark.parametrize(('call', 'message'), [
    (lambda p: p.step(np.zeros((2, 5)), 0.2), r'pressure_command of shape \(1, 5\)'),
    (lambda p: p.step(np.full(5, np.nan), 0.2), 'finite pressure_command'),
    (lambda p: p.step(np.zeros(5), 0.0), 'dt > 0'),
    (lambda p: p.holding_pressures([0.0, 0.0, 1.2]), 'PEA length outside'),
    (lambda p: p.holding_pressures([0.2, 0.0, 0.6]), 'bend beyond'),
    (lambda p: p.holding_pressures([0.0, 0.0]), r'end_point of shape \(3,\)'),
    (lambda p: p.static_end_point([-1.0, 0, 0, 0, 0]), 'non-negative pressures'),
    (lambda p: p.valve_voltage([np.inf]), r'finite p \[Pa\]'),
])
def test_bad_input_is_rejected(call, message):
    with pytest.raises(ValueError, match=message):
        call(SoftArmPlant())


def test_new_params_take_effect_and_keep_the_state():
    plant = SoftArmPlant()
    _hold(plant, _command(PEA=20, B4=20), 3.0)
    pressures, stretches = plant.chamber_pressures, plant.stretches
    plant.params = dataclasses.replace(plant.params, bend_skew=0.3, noise_radius_px=0.05)
    # the state (pressures, walls) is kept; the geometry is the new one at once
    np.testing.assert_array_equal(plant.chamber_pressures, pressures)
    np.testing.assert_array_equal(plant.stretches, stretches)
    _hold(plant, _command(PEA=20, B4=20), 10.0)
    # the bend of B4 alone now points 0.3 rad off +x
    x, y, _ = plant.end_point[0]
    assert np.arctan2(y, x) == pytest.approx(0.3, abs=0.05)
    with pytest.raises(ValueError, match='SoftArmPlantParams'):
        plant.params = {'noise_radius_px': 0.0}


def test_bad_construction_is_rejected():
    with pytest.raises(ValueError, match='n an integer >= 1'):
        SoftArmPlant(0)
    with pytest.raises(ValueError, match='pea_time_constant > 0'):
        SoftArmPlantParams(pea_time_constant=0.0)
    with pytest.raises(ValueError, match='finite pea_play'):
        SoftArmPlantParams(pea_play=np.nan)
    with pytest.raises(ValueError, match='camera a SraCamera'):
        SoftArmPlantParams(camera=None)
    with pytest.raises(ValueError, match='valve_delay >= 0'):
        SoftArmPlantParams(valve_delay=-0.1)
