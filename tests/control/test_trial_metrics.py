"""TrialMetrics: RMSE and reach time of a trial, against hand-checkable sequences."""

import numpy as np
import pytest

from inflarm_control.trial_metrics import TrialMetrics


def test_rmse_per_axis_is_the_root_mean_square_error():
    rng = np.random.default_rng(7)
    target = np.array([0.1, 0.11, 0.67])
    samples = target + rng.normal(0.0, 0.01, (40, 3))
    metrics = TrialMetrics(target, tolerance=0.005)
    for k, sample in enumerate(samples):
        metrics.add(sample, 0.2 * k)
    expected = np.sqrt(np.mean((samples - target) ** 2, axis=0))
    np.testing.assert_allclose(metrics.rmse[0], expected, rtol=1e-12)
    assert metrics.samples == 40


def test_reach_time_is_the_start_of_the_final_stay_within_tolerance():
    metrics = TrialMetrics([0.0, 0.0, 0.0], tolerance=0.01)
    # x: enters at t=1, leaves at t=2, re-enters at t=3 and stays -> 3.0
    # y: inside from the first sample -> 0.0
    # z: never inside -> inf
    xs = [0.5, 0.0, 0.05, 0.0, 0.0]
    for k, x in enumerate(xs):
        metrics.add([x, 0.0, 1.0], float(k))
    assert metrics.reach_time[0].tolist() == [3.0, 0.0, np.inf]
    metrics.add([0.5, 0.0, 0.0], 5.0)  # x leaves again, z arrives
    assert metrics.reach_time[0].tolist() == [np.inf, 0.0, 5.0]


def test_batched_tasks_are_independent():
    metrics = TrialMetrics([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], tolerance=0.1)
    metrics.add([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], 0.0)
    metrics.add([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], 1.0)
    assert metrics.reach_time.tolist() == [[0.0] * 3, [1.0] * 3]
    np.testing.assert_allclose(metrics.rmse[1], np.sqrt(0.5))


def test_samples_without_a_measurement_count_for_nothing():
    metrics = TrialMetrics([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], tolerance=0.1)
    metrics.add([[0.3, 0.0, 0.0], [np.nan, np.nan, np.nan]], 0.0, valid=[True, False])
    metrics.add([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], 1.0)
    metrics.add([[np.nan, 0.0, 0.0], [1.0, 1.0, 1.0]], 2.0, valid=[False, True])
    assert metrics.samples == 3
    np.testing.assert_allclose(metrics.rmse[0], [np.sqrt(0.09 / 2), 0.0, 0.0])
    np.testing.assert_allclose(metrics.rmse[1], 0.0)  # two measured samples, both on target
    assert metrics.reach_time.tolist() == [[1.0, 0.0, 0.0], [1.0] * 3]
    with pytest.raises(ValueError, match=r'valid of shape \(2,\)'):
        metrics.add([[0.0] * 3, [1.0] * 3], 3.0, valid=[True])
    with pytest.raises(ValueError, match='finite end_point'):
        metrics.add([[np.nan, 0.0, 0.0], [1.0] * 3], 3.0, valid=[True, True])


@pytest.mark.parametrize('target, tolerance, match', [
    ([0.0, 0.0], 0.01, 'target of shape'),
    ([0.0, np.nan, 0.0], 0.01, 'finite target'),
    ([0.0, 0.0, 0.0], 0.0, 'tolerance > 0'),
])
def test_bad_construction_is_rejected(target, tolerance, match):
    with pytest.raises(ValueError, match=match):
        TrialMetrics(target, tolerance)


def test_bad_samples_are_rejected():
    metrics = TrialMetrics([0.0, 0.0, 0.0], tolerance=0.01)
    with pytest.raises(ValueError, match='finite end_point'):
        metrics.add([np.nan, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError, match='finite end_point'):
        metrics.add([0.0, 0.0], 0.0)
    assert metrics.samples == 0
