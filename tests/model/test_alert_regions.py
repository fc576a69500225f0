"""Alert regions and their repulsive term (4.3.2 of 001), shared by planning and control."""

import numpy as np
import pytest

from inflarm_model.alert_regions import check_regions, grow_boxes, regions_of, repulsive_offset
from inflarm_msgs_json import Cuboid, ObstacleSet

BOX = np.array([[[0.035, 0.04, 0.65], [0.14, 0.14, 0.78]]])


def test_the_offset_is_the_shortest_way_out_and_zero_outside():
    regions = grow_boxes(BOX, 0.01)
    np.testing.assert_allclose(repulsive_offset([0.03, 0.1, 0.7], regions), [-0.005, 0, 0],
                               atol=1e-12)
    np.testing.assert_array_equal(repulsive_offset([0.0, 0.13, 0.71], regions), 0.0)
    points = np.random.default_rng(7).uniform([0.02, 0.03, 0.64], [0.15, 0.15, 0.79], (50, 3))
    out = points + repulsive_offset(points, regions)
    inside = np.all((points >= regions[0, 0]) & (points <= regions[0, 1]), axis=-1)
    # on the surface after the push: one coordinate on a face, the others within
    on_face = np.isclose(out, regions[0, 0]) | np.isclose(out, regions[0, 1])
    assert np.all(on_face[inside].any(axis=-1))


def test_an_obstacle_set_gives_its_boxes_grown_by_its_margin():
    message = ObstacleSet('sra_mount', 0.03, (Cuboid(min=(0.035, 0.04, 0.65),
                                                     max=(0.14, 0.14, 0.78), name='box'),))
    np.testing.assert_allclose(regions_of(message), grow_boxes(BOX, 0.03))
    assert regions_of(ObstacleSet('sra_mount', 0.03, ())).shape == (0, 2, 3)


def test_bad_regions_and_margins_are_refused():
    with pytest.raises(ValueError, match=r'regions of shape \(K, 2, 3\)'):
        check_regions(np.zeros((2, 3)))
    with pytest.raises(ValueError, match='finite region corners'):
        check_regions([[[np.nan, 0, 0], [1, 1, 1]]])
    with pytest.raises(ValueError, match='min corner <= max corner, region 0'):
        check_regions(BOX[:, ::-1])
    with pytest.raises(ValueError, match='margin >= 0'):
        grow_boxes(BOX, -0.01)
    with pytest.raises(ValueError, match='finite end_point'):
        repulsive_offset([np.inf, 0, 0], BOX)
    with pytest.raises(ValueError, match='an ObstacleSet'):
        regions_of([BOX])
