"""PressureControlSession, the pressure controller's core, without ROS: trials, learning and
its file, vision dropouts, paths, venting."""

import numpy as np
import pytest

from inflarm_control.path_following import PathFollowingParams
from inflarm_control.pid_ilc import PidIlcParams
from inflarm_control.pressure_control import (
    PressureControlSession,
    TrialLimits,
    load_ilc_memories,
    task_key,
)
from inflarm_msgs_json import ControlTask

START = np.array([0.0, 0.0, 0.604])
TARGET = (0.100, 0.110, 0.670)
PARAMS = PidIlcParams()  # 5 Hz
STEP_NS = round(1e9 / PARAMS.rate_hz)


def session(tmp_path=None, **limits) -> PressureControlSession:
    return PressureControlSession(
        PARAMS, PathFollowingParams(), TrialLimits(**{'trial_duration': 1.0, **limits}),
        memory_path=None if tmp_path is None else tmp_path / 'memories.npz')


def run_steps(s: PressureControlSession, steps: int, start_ns: int = 0, measure: bool = True):
    """Steps at the control rate, each after a fresh measurement at START if ``measure``."""
    results = []
    for k in range(steps):
        now = start_ns + (k + 1) * STEP_NS
        if measure:
            s.measure(START, now)
        results.append(s.step(now))
    return results


def test_a_trial_reports_at_its_end_learns_into_the_file_and_seeds_the_next(tmp_path):
    s = session(tmp_path)
    s.measure(START, 0)
    assert s.start_task(ControlTask('sra_mount', TARGET, 'pid_ilc', 7)) == ('PID alone', None)
    steps = run_steps(s, 5)  # 1 s at 5 Hz; the end never moves
    assert [r.report is None for r in steps] == [True] * 4 + [False]
    report = steps[-1].report
    assert report.trial_index == 7
    np.testing.assert_allclose(report.rmse, np.abs(START - TARGET))  # every sample at START
    assert report.reach_time == (None, None, None)  # never within 5 mm
    assert not s.trial_active and steps[-1].command is not None
    memory = s.memories[task_key(TARGET)]
    assert memory.shape == (PARAMS.memory_steps, 5) and np.abs(memory).max() > 0.0
    stored = load_ilc_memories(tmp_path / 'memories.npz', PARAMS.memory_steps)
    np.testing.assert_array_equal(stored[task_key(TARGET)], memory)
    # a new session learns on from the file; plain PID ignores it
    again = session(tmp_path)
    again.measure(START, 0)
    assert again.start_task(ControlTask('sra_mount', TARGET, 'pid_ilc', 8))[0] == 'ILC memory'
    assert again.start_task(ControlTask('sra_mount', TARGET, 'pid', 9))[0] == 'PID alone'


def test_idle_steps_hold_the_last_command_and_a_dropout_holds_without_learning_a_sample():
    s = session()
    assert s.step(0).command is None  # nothing to hold yet
    s.measure(START, 0)
    s.start_task(ControlTask('sra_mount', TARGET, 'pid', 0))
    fresh = run_steps(s, 2)
    assert not any(r.stale for r in fresh)
    samples = s.metrics.samples
    late = 2 * STEP_NS + round(PARAMS.rate_hz * 1e9)  # 5 s after the last measurement
    dropout = s.step(late)
    assert dropout.stale and s.metrics.samples == samples
    np.testing.assert_array_equal(dropout.command, fresh[-1].command)
    s.stop()
    idle = s.step(late + STEP_NS)
    assert not s.trial_active and not idle.stale
    np.testing.assert_array_equal(idle.command, fresh[-1].command)
    assert s.memories == {}  # a stopped trial teaches nothing


def test_what_it_cannot_act_on_is_rejected_and_changes_nothing():
    s = session()
    with pytest.raises(ValueError, match='no ball_position received yet'):
        s.start_task(ControlTask('sra_mount', TARGET, 'pid', 0))
    with pytest.raises(ValueError, match='no ball_position received yet'):
        s.follow([START, TARGET])
    with pytest.raises(ValueError, match='ball_position'):
        s.measure((0.0, 0.0, 5.0), 0)
    assert s.position is None
    s.measure(START, 0)
    with pytest.raises(ValueError, match='waypoint'):
        s.follow([START, (0.0, 0.0, 5.0)])
    assert not s.following and not s.trial_active


def test_limits_replaced_between_steps_apply_to_the_trial_under_way():
    s = session()
    s.measure(START, 0)
    s.start_task(ControlTask('sra_mount', TARGET, 'pid', 0))
    assert all(r.report is None for r in run_steps(s, 3))
    s.limits = TrialLimits(trial_duration=2.0)
    reports = [r.report is not None for r in run_steps(s, 7, start_ns=3 * STEP_NS)]
    assert reports == [False] * 6 + [True]  # at step 10: 2 s at 5 Hz


def test_a_path_is_followed_from_the_held_pressures_and_a_task_ends_it():
    s = session()
    s.measure(START, 0)
    source, problem = s.follow([START + (0.0, 0.0, 0.01), START + (0.03, 0.0, 0.02)])
    assert (source, problem) == ('PI alone', None) and s.following
    first = run_steps(s, 3)
    assert all(r.command is not None and r.command.shape == (5,) for r in first)
    s.start_task(ControlTask('sra_mount', TARGET, 'pid', 1))
    assert s.trial_active and not s.following


def test_vent_holds_zero_and_reset_forgets_the_file_too(tmp_path):
    s = session(tmp_path)
    s.measure(START, 0)
    s.start_task(ControlTask('sra_mount', TARGET, 'pid_ilc', 0))
    run_steps(s, 5)
    assert len(s.memories) == 1
    s.start_task(ControlTask('sra_mount', TARGET, 'pid', 1))
    np.testing.assert_array_equal(s.vent(), np.zeros(5))
    assert not s.trial_active
    np.testing.assert_array_equal(s.step(10 * STEP_NS).command, np.zeros(5))
    assert s.reset_learning() == 1
    assert load_ilc_memories(tmp_path / 'memories.npz', PARAMS.memory_steps) == {}


def test_a_file_that_is_not_one_of_memories_is_named(tmp_path):
    bad = tmp_path / 'memories.npz'
    np.savez(bad, targets_mm=np.zeros((1, 3)), memories=np.zeros((1, 3, 5)))
    with pytest.raises(ValueError, match=f"'{bad}' is not an ILC memory file"):
        session(tmp_path)
