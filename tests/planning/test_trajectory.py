"""From the grid path to a timed trajectory: simplify, shortcut, smooth, resample, timing."""

import numpy as np
import pytest

from inflarm_planning.astar import Cuboid, NoPathError, plan_path
from inflarm_planning.collision import box_array
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
from inflarm_planning.trajectory import (
    make_trajectory,
    path_length,
    plan_trajectory,
    resample,
    shortcut,
    simplify,
    smooth,
    time_parameterize,
)
from planning_reference import violations

PAPER = [OBSTACLE.bounds]


def test_simplify_keeps_only_the_turns():
    path = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0], [2, 1, 0], [2, 2, 1], [2, 3, 2],
                     [1, 3, 2]], dtype=float)
    np.testing.assert_array_equal(simplify(path), [[0, 0, 0], [2, 0, 0], [2, 1, 0], [2, 3, 2],
                                                   [1, 3, 2]])
    back = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0, 0]], dtype=float)  # a reversal is a turn
    np.testing.assert_array_equal(simplify(back), back)


def test_shortcut_goes_straight_where_free_and_around_the_box_where_not():
    boxes = box_array([OBSTACLE], 0.01)
    open_path = np.array([[0.0, -0.1, 0.7], [0.0, -0.05, 0.7], [0.05, -0.05, 0.7],
                          [0.1, -0.1, 0.7]])
    np.testing.assert_array_equal(shortcut(open_path, boxes), open_path[[0, -1]])
    grid = simplify(plan_path(START, GOAL, [OBSTACLE], 0.005, 0.01))
    short = shortcut(grid, boxes)
    assert 3 <= len(short) < len(grid)
    assert path_length(short) < path_length(grid)
    assert violations(short, PAPER, 0.01) == []
    # every kept point is a point of the input
    assert all(np.any(np.all(grid == p, axis=1)) for p in short)


def test_smooth_cuts_free_corners_and_keeps_the_ends():
    path = np.array([[0.0, -0.1, 0.7], [0.1, -0.1, 0.7], [0.1, 0.0, 0.7]])
    rounded = smooth(path, np.zeros((0, 2, 3)), iterations=2)
    np.testing.assert_array_equal(rounded[[0, -1]], path[[0, -1]])
    assert len(rounded) == 2 + 4  # the corner became 2 points, then each of those 2
    assert path_length(rounded) < path_length(path)
    # with a box right in the corner, the cut is refused and the corner kept
    corner_box = box_array([Cuboid((0.06, -0.099, 0.70), (0.099, -0.06, 0.72))])
    np.testing.assert_array_equal(smooth(path, corner_box, iterations=1), path)
    with pytest.raises(ValueError, match='iterations to be an int >= 0'):
        smooth(path, corner_box, iterations=-1)


def test_resample_bounds_the_spacing_and_keeps_the_vertices():
    path = np.array([[0.0, 0.0, 0.6], [0.012, 0.0, 0.6], [0.012, 0.0, 0.6049]])
    dense = resample(path, 0.005)
    steps = np.linalg.norm(np.diff(dense, axis=0), axis=1)
    assert steps.max() <= 0.005 + 1e-15
    assert all(np.any(np.all(np.isclose(dense, p), axis=1)) for p in path)
    assert len(dense) == 1 + 3 + 1
    assert path_length(dense) == pytest.approx(path_length(path))
    with pytest.raises(ValueError, match='max_step > 0'):
        resample(path, 0.0)


def test_time_parameterize_is_a_trapezoid():
    path = resample(np.array([[0.0, 0.0, 0.6], [0.2, 0.0, 0.6]]), 0.001)
    t = time_parameterize(path, max_speed=0.01, max_accel=0.005)
    # ramps of 2 s over 1 cm each, 18 cm cruising at 1 cm/s
    assert t[0] == 0.0 and t[-1] == pytest.approx(20.0 + 2.0)
    assert np.all(np.diff(t) > 0)
    speed = np.linalg.norm(np.diff(path, axis=0), axis=1) / np.diff(t)
    assert speed.max() <= 0.01 + 1e-9
    i = np.searchsorted(t, 1.0)
    assert path[i, 0] == pytest.approx(0.0025, abs=1e-3)  # a t^2 / 2 at t = 1 s
    short = resample(np.array([[0.0, 0.0, 0.6], [0.01, 0.0, 0.6]]), 0.001)
    t_short = time_parameterize(short, 0.01, 0.005)
    assert t_short[-1] == pytest.approx(2.0 * np.sqrt(0.01 / 0.005))  # never at full speed
    with pytest.raises(ValueError, match='repeated points'):
        time_parameterize(np.array([[0, 0, 0.6], [0, 0, 0.6]]), 0.01, 0.01)


@pytest.mark.parametrize('margin', [0.01, ALERT_MARGIN])
def test_the_papers_trajectory_is_free_shorter_and_timed(margin):
    planned = plan_trajectory(START, GOAL, [OBSTACLE], 0.005, margin, max_step=0.005,
                              max_speed=0.005, max_accel=0.005)
    trajectory = planned.trajectory
    assert violations(trajectory.points, PAPER, margin) == []
    np.testing.assert_array_equal(trajectory.points[[0, -1]], [START, GOAL])
    assert trajectory.length < planned.grid.length
    steps = np.linalg.norm(np.diff(trajectory.points, axis=0), axis=1)
    assert steps.max() <= 0.005 + 1e-12
    assert np.all(np.diff(trajectory.times) > 0)
    assert trajectory.duration == pytest.approx(trajectory.length / 0.005 + 0.005 / 0.005)


def test_random_trajectories_stay_free():
    rng = np.random.default_rng(7)
    made = 0
    for _ in range(12):
        centre = rng.uniform([-0.1, -0.1, 0.68], [0.1, 0.1, 0.85])
        half = rng.uniform(0.015, 0.05, 3)
        box = Cuboid(tuple(centre - half), tuple(centre + half))
        start = centre + rng.choice([-1, 1], 3) * (half + 0.04)
        goal = centre - np.sign(start - centre) * (half + 0.04)
        try:
            path = plan_path(start, goal, [box], 0.005, 0.01)
        except NoPathError:  # a start or goal the arm cannot reach: next
            continue
        trajectory = make_trajectory(path, [box], 0.01)
        assert violations(trajectory.points, [box.bounds], 0.01) == []
        assert trajectory.length <= path_length(path) + 1e-12
        made += 1
    assert made >= 6


def test_plan_trajectory_validates_before_searching():
    with pytest.raises(ValueError, match='max_speed > 0'):
        plan_trajectory(START, GOAL, [OBSTACLE], 0.005, 0.01, max_speed=0.0)
    with pytest.raises(ValueError, match='iterations'):
        plan_trajectory(START, GOAL, [OBSTACLE], 0.005, 0.01, smoothing=1.5)
