"""The soft arm's loop closed through the camera, in-process: the plant (valve delay on), the
simulated camera rendering its true end point, the vision pipeline ball_tracker runs, and the
PID + ILC controller (what ``inflarm-sra-experiments`` runs)."""

import numpy as np
import pytest

from inflarm_bringup.sra_experiments import (
    FIG7_START,
    FIG7_TARGET,
    MeasuredPlant,
    run_experiment,
)
from inflarm_control.pid_ilc import PidIlcController, run_trials
from inflarm_hw.sra_plant import NOISE_FREE, SoftArmPlant
from inflarm_hw.synthetic_camera import SraCamera

TARGET = np.array(FIG7_TARGET)


def test_the_loop_through_the_camera_reaches_the_fig7_target():
    # a memory learned without the camera (30 trials of 20 s, as the knowledge database
    # learns), then one trial measured only through the camera
    learned = run_trials(SoftArmPlant(1, NOISE_FREE), PidIlcController(1), FIG7_START,
                         FIG7_TARGET, 30, 20.0, keep_trajectories=False)
    plant = MeasuredPlant(SoftArmPlant(1, rng=np.random.default_rng(7)), SraCamera(), seed=7)
    r = run_trials(plant, PidIlcController(1), FIG7_START, FIG7_TARGET, 1, 10.0,
                   memory=learned.memory)
    assert (plant.frames, plant.dropouts) == (51, 0)
    # every axis within 7 s (measured: 5.2, 6.4, 5.4 s; y is the camera's depth axis)
    assert np.all(r.reach_time[0, 0] <= 7.0), r.reach_time
    truth = np.array(plant.truth)
    # the true end within 2 mm after 10 s (measured: -0.3, -1.0, +1.0 mm)
    assert np.all(np.abs(truth[-1] - TARGET) < 2e-3), truth[-1] - TARGET
    # what the camera saw is the true end point: across the line of sight (x, z) to a fraction
    # of a millimetre, along it (y, depth from the ball's apparent size) to a few
    error = np.abs(r.trajectories[0, :, 0] - truth).max(axis=0)
    assert error[0] < 1e-3 and error[2] < 1e-3 and error[1] < 4e-3, error


def test_the_controller_learns_through_the_camera():
    experiment = run_experiment(n_trials=4, duration_s=8.0, measurement='camera', seed=7)
    assert (experiment.frames, experiment.dropouts) == (4 * 41, 0)
    rmse = experiment.results.rmse[:, 0]
    assert np.all(np.diff(rmse, axis=0) < 0.0), rmse
    # z, driven by the slow PEA chamber, learns the slowest (measured: 0.73, 0.74, 0.78)
    assert np.all(rmse[-1] < np.array([0.8, 0.8, 0.85]) * rmse[0]), rmse
    # the true end point did the same (the camera's error is small against the RMSE)
    np.testing.assert_allclose(experiment.true_rmse, rmse, atol=1e-3)
    assert experiment.label == 'camera + ball tracker, valve delay 0.10 s'


def test_only_a_one_arm_plant_is_measured_through_the_camera():
    with pytest.raises(ValueError, match='plant of one arm'):
        MeasuredPlant(SoftArmPlant(2), SraCamera())
    with pytest.raises(ValueError, match='measurement in'):
        run_experiment(n_trials=1, duration_s=1.0, measurement='stereo')
