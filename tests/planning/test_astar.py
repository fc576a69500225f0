"""A* planning: the paper's scenario, seeded random scenarios, optimality, errors."""

import numpy as np
import pytest

from inflarm_model.soft_arm import WORKSPACE_POSITIVE
import inflarm_msgs_json
from inflarm_planning.astar import Cuboid, NoPathError, plan, plan_path
from inflarm_planning.free_space import free_space
from inflarm_planning.grid_search import STEP_COSTS, grid_distance, kind_costs
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
from planning_reference import (
    axes_clear_of_alert_regions,
    neighbourhood,
    shortest_costs,
    strictly_inside,
    violations,
)

PAPER = [OBSTACLE.bounds]


def length(path):
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def check_path(path, start, goal, obstacles, margin):
    """Shape, ends, work space and the independent collision check."""
    assert path.ndim == 2 and path.shape[1] == 3 and len(path) >= 2
    np.testing.assert_array_equal(path[0], start)
    np.testing.assert_array_equal(path[-1], goal)
    w = WORKSPACE_POSITIVE
    assert np.all(np.abs(path[:, :2]) <= w.x_max + 1e-12)
    assert np.all((path[:, 2] >= w.z_min - 1e-12) & (path[:, 2] <= w.z_max + 1e-12))
    assert violations(path, obstacles, margin) == []
    # at the path's points (grid points and ends) the axes keep out of the alert regions too
    assert axes_clear_of_alert_regions(path, obstacles, margin).all()


# --- the paper's scenario ----------------------------------------------------------------------


@pytest.mark.parametrize(('resolution', 'margin'), [(0.01, 0.01), (0.005, 0.01),
                                                     (0.005, ALERT_MARGIN), (0.002, 0.01)])
def test_the_papers_scenario(resolution, margin):
    path = plan_path(START, GOAL, [OBSTACLE], resolution, margin)
    check_path(path, START, GOAL, PAPER, margin)
    # around the near corner of the obstacle: longer than the straight line, by a bounded detour
    straight = np.linalg.norm(np.subtract(GOAL, START))
    assert 1.2 * straight < length(path) < 1.45 * straight
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert np.all(steps <= np.sqrt(3) * resolution + 1e-12)


def test_the_papers_scenario_with_the_cost_of_eq_7():
    default = plan(START, GOAL, [OBSTACLE], 0.005, ALERT_MARGIN)
    paper = plan(START, GOAL, [OBSTACLE], 0.005, ALERT_MARGIN, cost='paper')
    check_path(paper.path, START, GOAL, PAPER, ALERT_MARGIN)
    assert paper.cost == 'paper'
    # the default cost gives a shortest grid path; eq. (7) minimises the Manhattan length
    assert default.length <= paper.length + 1e-12
    manhattan = np.abs(np.diff(paper.path, axis=0)).sum()
    assert manhattan <= np.abs(np.diff(default.path, axis=0)).sum() + 1e-12


@pytest.mark.parametrize('connectivity', [6, 18, 26])
@pytest.mark.parametrize('cost', ['length', 'paper'])
def test_the_path_is_a_shortest_grid_path(connectivity, cost):
    """Same cost as Dijkstra (scipy) over the grid graph built independently from the free
    points, for each neighbourhood and cost."""
    resolution, margin = 0.01, 0.01
    result = plan(START, GOAL, [OBSTACLE], resolution, margin, cost=cost,
                  connectivity=connectivity)
    assert result.connectivity == connectivity
    free = free_space([OBSTACLE], resolution, margin).free
    first, last = result.cells[0], result.cells[-1]
    reference = 'length' if cost == 'length' else 'manhattan'
    optimum = shortest_costs(free, first, connectivity, reference)[tuple(last)]
    steps = np.diff(result.cells, axis=0)
    found = (np.linalg.norm(steps, axis=1) if cost == 'length' else np.abs(steps).sum(axis=1))
    assert found.sum() == pytest.approx(optimum, rel=1e-6)
    assert result.searches >= 1 and result.expanded > 0


@pytest.mark.parametrize('connectivity', [6, 18, 26])
def test_each_connectivity_plans_the_papers_scenario_with_its_own_steps(connectivity):
    result = plan(START, GOAL, [OBSTACLE], 0.005, ALERT_MARGIN, connectivity=connectivity)
    check_path(result.path, START, GOAL, PAPER, ALERT_MARGIN)
    allowed = {tuple(m) for m in neighbourhood(connectivity)}
    steps = {tuple(m) for m in np.diff(result.cells, axis=0)}
    assert steps <= allowed, steps - allowed
    if connectivity > 6:  # the larger neighbourhood's own steps are used
        smaller = {tuple(m) for m in neighbourhood(6 if connectivity == 18 else 18)}
        assert steps - smaller


def test_the_path_shortens_as_the_neighbourhood_grows():
    # the figures of inflarm_planning/README.md (grid path lengths, 5 mm, margin 30 mm)
    lengths = {c: plan(START, GOAL, [OBSTACLE], 0.005, ALERT_MARGIN, connectivity=c).length
               for c in (6, 18, 26)}
    assert lengths[6] >= lengths[18] >= lengths[26]
    np.testing.assert_allclose([lengths[c] * 1e3 for c in (6, 18, 26)],
                               [280.0, 259.50, 258.05], atol=0.01)


def test_the_larger_neighbourhoods_come_closer_to_the_straight_line():
    # the worst ratio of the obstacle-free grid length to the straight line, over directions
    # (inflarm_planning/README.md: 1.73 / 1.39 / 1.13 for 6 / 18 / 26 neighbours)
    one, two, three = kind_costs(STEP_COSTS['length'])
    deltas = np.argwhere(np.ones((25, 25, 25), dtype=bool))[1:]
    worst = {c: max(grid_distance(*(int(v) for v in d), c, one, two, three) / np.linalg.norm(d)
                    for d in deltas) for c in (6, 18, 26)}
    assert worst[6] == pytest.approx(np.sqrt(3.0))
    assert worst[18] == pytest.approx((1.0 + np.sqrt(2.0)) / np.sqrt(3.0))
    assert 1.12 < worst[26] < 1.13


@pytest.mark.parametrize('connectivity', [6, 18, 26])
@pytest.mark.parametrize('cost', ['length', 'paper'])
def test_the_heuristic_is_the_obstacle_free_distance_so_admissible_and_consistent(
        connectivity, cost):
    """``grid_distance`` equals Dijkstra's distance on an empty grid (so it never overestimates
    a path among obstacles), and no step lowers ``cost + h`` (consistency)."""
    n = 7
    centre = np.array([n // 2] * 3)
    reference = 'length' if cost == 'length' else 'manhattan'
    exact = shortest_costs(np.ones((n, n, n), dtype=bool), centre, connectivity, reference)
    one, two, three = kind_costs(STEP_COSTS[cost])
    cells = np.argwhere(np.ones((n, n, n), dtype=bool))
    h = np.array([grid_distance(*(int(v) for v in c - centre), connectivity, one, two, three)
                  for c in cells])
    np.testing.assert_allclose(h, exact[tuple(cells.T)], atol=1e-12)
    for move in neighbourhood(connectivity):
        step = np.linalg.norm(move) if cost == 'length' else float(np.abs(move).sum())
        for c in cells[::7]:
            a = grid_distance(*(int(v) for v in c), connectivity, one, two, three)
            b = grid_distance(*(int(v) for v in c + move), connectivity, one, two, three)
            assert a <= step + b + 1e-12


# --- random scenarios --------------------------------------------------------------------------


def random_scenario(rng):
    w = WORKSPACE_POSITIVE
    boxes = []
    for _ in range(int(rng.integers(1, 5))):
        centre = rng.uniform([-0.15, -0.15, 0.62], [0.15, 0.15, 0.92])
        half = rng.uniform(0.01, 0.05, 3)
        boxes.append(Cuboid(tuple(centre - half), tuple(centre + half), f'box{len(boxes)}'))
    low = np.array([-w.x_max, -w.y_max, w.z_min])
    high = np.array([w.x_max, w.y_max, w.z_max])
    start, goal = rng.uniform(low, high), rng.uniform(low, high)
    return boxes, start, goal


def test_seeded_random_scenarios():
    rng = np.random.default_rng(7)
    margin, resolution = 0.01, 0.005
    planned = reasons = 0
    seen = set()
    for _ in range(24):
        boxes, start, goal = random_scenario(rng)
        try:
            path = plan_path(start, goal, boxes, resolution, margin)
        except NoPathError as err:
            seen.add(err.reason)
            reasons += 1
            continue
        planned += 1
        check_path(path, start, goal, [b.bounds for b in boxes], margin)
    assert planned >= 12, (planned, seen)
    assert seen <= set(NoPathError.REASONS)


def test_start_and_goal_off_the_grid_are_joined_in_a_straight_free_line():
    start, goal = (0.0013, 0.1287, 0.7104), (0.1309, -0.0021, 0.7296)
    path = plan_path(start, goal, [OBSTACLE], 0.01, 0.01)
    check_path(path, np.array(start), np.array(goal), PAPER, 0.01)
    assert np.linalg.norm(path[1] - path[0]) <= np.sqrt(3) * 0.01


def test_a_message_cuboid_and_an_obstacle_set_are_accepted():
    message = OBSTACLE.to_message()
    a = plan_path(START, GOAL, [message], 0.01, 0.01)
    b = plan_path(START, GOAL, inflarm_msgs_json.ObstacleSet('sra_mount', 0.0, (message,)),
                  0.01, 0.01)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, plan_path(START, GOAL, [OBSTACLE], 0.01, 0.01))


def test_no_obstacles_give_a_straight_grid_path():
    path = plan_path((0.0, 0.0, 0.6), (0.1, 0.0, 0.6), [], 0.01, 0.01)
    np.testing.assert_allclose(path[:, 1:], [[0.0, 0.6]] * len(path), atol=1e-12)
    assert length(path) == pytest.approx(0.1)


def test_the_kernel_releases_the_gil():
    from inflarm_planning import grid_search

    assert grid_search._astar.targetoptions.get('nogil') is True


# --- no path -----------------------------------------------------------------------------------


@pytest.mark.parametrize(('start', 'goal', 'reason', 'match'), [
    ((0.1, 0.1, 0.7), GOAL, 'start_blocked', r"start \[0\.1, 0\.1, 0\.7\] m is not free: the "
     r"end is inside obstacle 0 'paper obstacle'"),
    (START, (0.03, 0.1, 0.7), 'goal_blocked', 'the end is inside the alert region of obstacle 0'),
    (START, (0.17, 0.17, 0.72), 'goal_blocked', 'the PEA2 axis crosses the alert region'),
    (START, (0.3, 0.0, 0.7), 'outside_workspace', r'goal x = 0\.300 m above the workspace '
     r'maximum 0\.202 m'),
    ((0.0, 0.0, 0.5), GOAL, 'outside_workspace', 'start z = 0.500 m below the workspace minimum'),
])
def test_no_path_errors_say_why(start, goal, reason, match):
    with pytest.raises(NoPathError, match=match) as error:
        plan_path(start, goal, [OBSTACLE], 0.01, 0.01)
    assert error.value.reason == reason


def test_a_goal_walled_off_has_no_connection():
    # a cross of walls through the z axis (above the PBA, so PEA1 is never touched) parts the
    # quadrants: from the second quadrant there is no way into the fourth
    z = (0.55, 1.0)
    walls = [Cuboid((-0.005, 0.0, z[0]), (0.005, 0.25, z[1])),
             Cuboid((-0.005, -0.25, z[0]), (0.005, 0.0, z[1])),
             Cuboid((0.0, -0.005, z[0]), (0.25, 0.005, z[1])),
             Cuboid((-0.25, -0.005, z[0]), (0.0, 0.005, z[1]))]
    with pytest.raises(NoPathError, match='no connection .* the open set emptied') as error:
        plan_path((-0.1, 0.1, 0.75), (0.1, -0.1, 0.75), walls, 0.005, 0.0)
    assert error.value.reason == 'no_connection'
    path = plan_path((-0.1, 0.1, 0.75), (-0.15, 0.05, 0.7), walls, 0.005, 0.0)  # same quadrant
    check_path(path, (-0.1, 0.1, 0.75), (-0.15, 0.05, 0.7), [w.bounds for w in walls], 0.0)


def test_a_start_whose_grid_neighbours_are_all_blocked_is_refused():
    # the start sits between two small boxes that hold both grid points of its 5 mm cell but
    # neither the start nor its arm
    start = (0.1, 0.0, 0.7025)
    boxes = [Cuboid((0.095, -0.005, 0.704), (0.105, 0.005, 0.72)),
             Cuboid((0.0995, -0.003, 0.695), (0.106, 0.003, 0.7005))]
    with pytest.raises(NoPathError, match='no free grid point in reach') as error:
        plan_path(start, GOAL, boxes, 0.005, 0.0)
    assert error.value.reason == 'start_blocked'
    path = plan_path(start, GOAL, boxes, 0.0025, 0.0)  # on the grid at 2.5 mm
    check_path(path, start, GOAL, [b.bounds for b in boxes], 0.0)


# --- bad input ---------------------------------------------------------------------------------


@pytest.mark.parametrize(('kwargs', 'match'), [
    ({'start': (np.nan, 0.13, 0.71)}, 'finite start'),
    ({'goal': (0.1, 0.0)}, r'goal of shape \(3,\)'),
    ({'goal': START}, 'start != goal'),
    ({'resolution': 0.0}, 'resolution > 0'),
    ({'resolution': 0.0005}, 'too fine for memory'),
    ({'resolution': 0.15}, 'coarser than the alert region'),
    ({'alert_margin': -0.01}, 'alert_margin >= 0'),
    ({'cost': 'manhattan'}, "cost in \\['length', 'paper'\\]"),
    ({'connectivity': 8}, r"connectivity in \(6, 18, 26\), got 8 .*the paper's eight"),
    ({'connectivity': 26.0}, r'connectivity in \(6, 18, 26\)'),
    ({'connectivity': True}, r'connectivity in \(6, 18, 26\)'),
    ({'obstacles': [(0, 0, 0)]}, r'obstacles\[0\] to be a Cuboid'),
])
def test_bad_arguments_raise_value_errors_naming_them(kwargs, match):
    arguments = {'start': START, 'goal': GOAL, 'obstacles': [OBSTACLE], 'resolution': 0.01,
                 'alert_margin': 0.01, **kwargs}
    with pytest.raises(ValueError, match=match):
        plan_path(**arguments)


def test_the_grid_points_of_the_path_are_on_the_lattice_and_free():
    result = plan(START, GOAL, [OBSTACLE], 0.005, 0.01)
    space = result.free_space
    assert space.is_free(result.cells).all()
    np.testing.assert_allclose(result.path, space.lattice.points(result.cells), atol=1e-12)
    low, high = OBSTACLE.grown(0.01).bounds
    assert not strictly_inside(result.path, low, high).any()
