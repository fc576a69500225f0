"""The physical SRA model against the paper (001_..., sections 2.2, 3.3, 4.3.2), no ROS."""

import numpy as np
import pytest

from inflarm_control.pid_ilc import PidIlcController, PidIlcParams, run_trials
from inflarm_hw.sra_plant import (
    NOISE_FREE,
    SoftArmPlant,
    SoftArmPlantParams,
    wall_pressure,
    wall_stretch,
)
from inflarm_model.soft_arm import CHAMBERS

PEA, B1, B2, B3, B4 = (CHAMBERS.index(c) for c in CHAMBERS)
FIG7_START = (0.0, 0.0, 0.604)
FIG7_TARGET = (0.100, 0.110, 0.670)


def _work_space(plant, n=11):
    """Static end points over 0-100 kPa: the PEA and each quadrant's two bellows (Fig 4)."""
    g = np.linspace(0.0, 100e3, n)
    pea, first, second = (a.ravel() for a in np.meshgrid(g, g, g, indexing='ij'))
    points = []
    for pair in ((B3, B4), (B2, B3), (B1, B2), (B1, B4)):
        pressures = np.zeros((pea.size, 5))
        pressures[:, PEA], pressures[:, pair[0]], pressures[:, pair[1]] = pea, first, second
        points.append(plant.static_end_point(pressures))
    return np.concatenate(points)


def test_work_space_extremes_are_fig_5a_within_5_percent():
    points = _work_space(SoftArmPlant())
    # Fig 5A: X, Y -202..202 mm, Z 574..990 mm
    for axis in (0, 1):
        assert points[:, axis].max() == pytest.approx(0.202, rel=0.05)
        assert points[:, axis].min() == pytest.approx(-0.202, rel=0.05)
    assert points[:, 2].min() == pytest.approx(0.574, rel=0.05)
    assert points[:, 2].max() == pytest.approx(0.990, rel=0.05)


def test_the_envelope_is_curved_and_z_falls_as_the_bend_grows():
    plant = SoftArmPlant()
    bellows = np.linspace(0.0, 100e3, 21)
    for pea in (0.0, 30e3, 100e3):
        pressures = np.zeros((bellows.size, 5))
        pressures[:, PEA], pressures[:, B4] = pea, bellows
        end = plant.static_end_point(pressures)
        assert np.all(np.diff(end[:, 0]) > 0.0)  # bends further towards +x (B4, Fig 4)
        assert np.all(np.diff(end[:, 2]) < 0.0)  # and z falls
    # the fully bent rim: its x grows with the PEA's length less than in proportion (the
    # weight of PEA2 and the end bends a longer arm back), so the envelope is curved
    pressures = np.zeros((11, 5))
    pressures[:, PEA], pressures[:, B4] = np.linspace(0.0, 100e3, 11), 100e3
    rim = plant.static_end_point(pressures)
    slope = np.diff(rim[:, 0]) / np.diff(rim[:, 2])
    assert np.all(slope > 0.0) and slope[-1] < 0.8 * slope[0]
    assert rim[0, 2] < FIG7_START[2] - 0.02  # the lowest points are bent, off the axis


def test_the_walls_are_neo_hookean():
    modulus = SoftArmPlantParams().pea_modulus
    pressure = np.array([0.0, 1e3, 20e3, 100e3, 400e3])
    stretch = wall_stretch(pressure, modulus)
    np.testing.assert_allclose(wall_pressure(stretch, modulus), pressure, rtol=1e-6, atol=1e-6)
    assert stretch[0] == 1.0
    # softening: the stretch per pascal grows with the stretch
    gain = np.diff(stretch) / np.diff(pressure)
    assert np.all(np.diff(gain) > 0.0)
    # identified from Z max: both PEAs and the PBA 0.990 m long at 100 kPa
    p = SoftArmPlantParams()
    length = 2.0 * p.pea_rest_length * wall_stretch(100e3, modulus) + p.pba_length
    assert length == pytest.approx(0.990, abs=1e-3)


def test_commands_in_the_dead_zone_move_nothing():
    plant = SoftArmPlant(1, NOISE_FREE)
    for _ in range(50):
        plant.step(np.full(5, 3.99e3), 0.2)
    np.testing.assert_array_equal(plant.chamber_pressures, 0.0)
    np.testing.assert_allclose(plant.end_point, [FIG7_START], atol=1e-12)
    plant.step(np.full(5, 4.0e3), 0.2)  # at the dead zone's edge the valves deliver
    assert np.all(plant.chamber_pressures > 0.0)


def test_nothing_moves_before_the_transport_delay():
    plant = SoftArmPlant(1, NOISE_FREE)
    delay = plant.params.valve_delay
    assert delay == 0.1  # the documented default
    command = np.array([30e3, 0.0, 0.0, 30e3, 30e3])
    for _ in range(4):  # 0.08 s
        plant.step(command, 0.02)
    np.testing.assert_allclose(plant.end_point, [FIG7_START], atol=1e-12)
    plant.step(command, 0.02)  # 0.1 s: the command just arrived, nothing has flowed yet
    np.testing.assert_array_equal(plant.chamber_pressures, 0.0)
    plant.step(command, 0.02)
    assert np.all(plant.chamber_pressures[0, [PEA, B3, B4]] > 0.0)
    assert plant.end_point[0, 2] > FIG7_START[2]


def test_stretching_expands_the_gas():
    """Gas-structure coupling (2.1): a chamber whose wall still creeps loses pressure to its
    growing volume, so it trails an ideal first-order fill."""
    plant = SoftArmPlant(1, NOISE_FREE)
    p = plant.params
    for _ in range(10):
        plant.step(np.array([50e3, 0.0, 0.0, 0.0, 0.0]), 0.1)
    rigid = 50e3 * -np.expm1(-(1.0 - p.valve_delay) / p.pea_time_constant)
    assert plant.chamber_pressures[0, PEA] < rigid


def _fig7(seed, params=None, n_trials=30):
    plant = SoftArmPlant(1, params or SoftArmPlantParams(), np.random.default_rng(seed))
    return run_trials(plant, PidIlcController(1, PidIlcParams()), FIG7_START, FIG7_TARGET,
                      n_trials, 20.0, keep_trajectories=False)


@pytest.fixture(scope='module')
def fig7_runs():
    """The Fig 7 task, 30 trials of 20 s at 5 Hz, default plant and controller, noise on."""
    return [_fig7(seed) for seed in (1, 2, 3, 4)]


def test_fig7_trial_1_pid_alone_reaches_no_axis_within_15_s(fig7_runs):
    for run in fig7_runs:
        assert np.all(run.reach_time[0, 0] > 15.0)


def test_fig7_trial_30_reaches_x_and_z_in_4_to_7_s(fig7_runs):
    for run in fig7_runs:
        x, _, z = run.reach_time[-1, 0]
        assert 4.0 <= x <= 7.0
        assert 4.0 <= z <= 7.0


def test_fig7_trial_30_reaches_y_in_6_to_10_s_the_slowest_axis(fig7_runs):
    # the paper: y in about 8 s, after x and z (measured: 6.8-7.4 s, against 5.2-5.8 s for x
    # and z); the same measured exactly, so y's time is the arm's, not the camera's depth noise
    reach = np.array([run.reach_time[-1, 0] for run in fig7_runs])  # (seeds, 3)
    assert np.all((reach[:, 1] >= 6.0) & (reach[:, 1] <= 10.0)), reach
    assert np.all(reach[:, 1] > reach[:, [0, 2]].max(axis=1)), reach
    exact = _fig7(1, SoftArmPlantParams(noise_center_px=0.0, noise_radius_px=0.0))
    assert 6.0 <= exact.reach_time[-1, 0, 1] <= 10.0


def test_fig7_trial_rmse_does_not_rise_after_trial_3(fig7_runs):
    for run in fig7_runs:
        rmse = run.rmse[:, 0]  # (trials, 3)
        rises = np.diff(rmse[2:], axis=0)
        # within the noise: the camera's noise moves a trial's y RMSE (about 25 mm over 100
        # samples) by ~0.1 mm; rises up to 0.26 mm (1 %) occur in y, under 0.05 mm in x, z
        assert np.all(rises[:, [0, 2]] < 0.1e-3)
        assert np.all(rises[:, 1] < 0.5e-3)
        assert np.all(rmse[-1] < 0.5 * rmse[0])
