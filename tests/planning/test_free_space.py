"""The planning grid: lattice, free points by eq. 5, cache, validation."""

import numpy as np
import pytest

from inflarm_model.soft_arm import WORKSPACE_POSITIVE
from inflarm_planning.astar import Cuboid
from inflarm_planning.free_space import (
    Lattice,
    build_free_space,
    check_grid,
    clear_cache,
    free_space,
)
from inflarm_planning.scenario import GOAL, OBSTACLE, START
from planning_reference import axes_clear_of_alert_regions


def test_the_lattice_holds_the_papers_millimetres():
    for mm in (10, 5, 2, 1):
        lattice = Lattice.over(WORKSPACE_POSITIVE, mm * 1e-3)
        for point in (START, GOAL, (0.0, 0.0, 0.990), (-0.202 if mm in (2, 1) else -0.2, 0, 0.6)):
            index = lattice.nearest_index(point)
            assert lattice.contains(index)
            np.testing.assert_allclose(lattice.points(index), point, atol=1e-12)
    lattice = Lattice.over(WORKSPACE_POSITIVE, 0.001)
    assert lattice.shape == (405, 405, 417) and lattice.size == 68_398_425
    assert Lattice.over(WORKSPACE_POSITIVE, 0.005).shape == (81, 81, 84)


def test_free_points_agree_with_an_independent_check():
    space = build_free_space([OBSTACLE], 0.01, 0.01)
    index = np.stack(np.meshgrid(*(np.arange(n) for n in space.lattice.shape),
                                 indexing='ij'), axis=-1).reshape(-1, 3)
    points = space.lattice.points(index)
    free = space.free.reshape(-1)
    # points whose axes come near the obstacle (the rest are clear by any measure)
    near = np.flatnonzero((points[:, 0] > 0.0) & (points[:, 1] > 0.0) & (points[:, 2] > 0.6))
    bounds = [OBSTACLE.bounds]
    samples = 600  # along axes <= 1 m long: samples <= 1.7 mm apart
    touching_free, clear_free = (np.concatenate([
        axes_clear_of_alert_regions(points[near[k:k + 400]], bounds, 0.01, samples, clearance)
        for k in range(0, len(near), 400)]) for clearance in (0.0, 1.0 / samples))
    # a point the planner calls free has no axis sample inside an alert region, and a point whose
    # axes keep clear of them by more than the sample spacing is free; in between lie the
    # grazing cases (the planner's boxes are closed: touching is blocked, and the paper's
    # millimetres put many grid points exactly on an alert region's surface)
    assert np.all(free[near] <= touching_free)
    assert np.all(free[near] >= clear_free)
    assert np.count_nonzero(touching_free & ~free[near]) > 100  # surface cases are tested
    assert free[np.setdiff1d(np.arange(len(free)), near)].all()
    assert 0.8 < free.mean() < 0.9
    assert not space.padded.flags.writeable
    assert space.padded[0].sum() == 0 and space.padded[:, :, -1].sum() == 0


def test_no_obstacles_leave_everything_free():
    space = build_free_space([], 0.02, 0.01)
    assert space.free.all()


def test_the_cache_returns_the_same_grid_for_the_same_obstacles():
    clear_cache()
    first = free_space([OBSTACLE], 0.01, 0.01)
    again = free_space([Cuboid(OBSTACLE.min_corner, OBSTACLE.max_corner, OBSTACLE.name)],
                       0.01, 0.01)
    assert again is first
    assert free_space([OBSTACLE], 0.01, 0.02) is not first
    assert first.build_time_s > 0.0


@pytest.mark.parametrize(('resolution', 'margin', 'match'), [
    (0.0, 0.01, 'resolution > 0'),
    (-0.01, 0.01, 'resolution > 0'),
    (float('nan'), 0.01, 'resolution > 0'),
    ('fine', 0.01, 'resolution to be a number'),
    (0.0008, 0.01, r'too fine for memory: 1\.33e\+08 grid points'),
    (0.05, 0.0, r'coarser than the alert region of obstacles\[0\]'),
    (0.01, -0.001, 'alert_margin >= 0'),
    (1.0, 0.01, 'leaves no grid point'),
])
def test_bad_grids_are_rejected_naming_the_argument(resolution, margin, match):
    thin = Cuboid((0.0, 0.0, 0.7), (0.1, 0.1, 0.74))
    with pytest.raises(ValueError, match=match):
        check_grid((thin,), resolution, margin, WORKSPACE_POSITIVE)
    with pytest.raises(ValueError, match=match):
        free_space([thin], resolution, margin)
