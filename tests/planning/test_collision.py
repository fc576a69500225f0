"""The collision model (eq. 5): boxes, segment tests, the arm's axes, distances, repulsion."""

import numpy as np
import pytest

from inflarm_model.soft_arm import WORKSPACE_POSITIVE, central_axes
import inflarm_msgs_json
from inflarm_planning.astar import Cuboid
from inflarm_planning.collision import (
    arm_collides,
    arm_contacts,
    as_cuboids,
    box_array,
    describe_collision,
    distance_to_boxes,
    motions_collide,
    points_in_boxes,
    repulsive_offset,
    segments_hit_boxes,
)
from planning_reference import axis_points, strictly_inside

BOX = Cuboid((0.035, 0.040, 0.650), (0.140, 0.140, 0.780), 'paper')


def random_end_points(rng, n):
    w = WORKSPACE_POSITIVE
    return rng.uniform([-w.x_max, -w.y_max, w.z_min], [w.x_max, w.y_max, w.z_max], (n, 3))


def dense_segment_hits(a, b, low, high, samples=4001):
    """Reference: does the segment come within 1e-12 of the closed box? (sampled)"""
    t = np.linspace(0.0, 1.0, samples)[None, :, None]
    hits = []
    for first in range(0, len(a), 200):
        sa, sb = a[first:first + 200], b[first:first + 200]
        q = sa[:, None, :] + t * (sb - sa)[:, None, :]
        hits.append(np.all((q >= low - 1e-12) & (q <= high + 1e-12), axis=-1).any(axis=1))
    return np.concatenate(hits)


# --- Cuboid ------------------------------------------------------------------------------------


def test_cuboid_normalises_and_converts_to_and_from_the_message():
    box = Cuboid([0, 0.1, 0.6], np.array([0.1, 0.2, 0.7]), 'b')
    assert box.min_corner == (0.0, 0.1, 0.6) and type(box.min_corner[0]) is float
    message = box.to_message()
    assert isinstance(message, inflarm_msgs_json.Cuboid)
    assert message.min == box.min_corner and message.max == box.max_corner
    assert Cuboid.from_message(message) == box
    assert hash(box) == hash(Cuboid.from_message(message))
    grown = box.grown(0.01)
    np.testing.assert_allclose(grown.bounds, [[-0.01, 0.09, 0.59], [0.11, 0.21, 0.71]])
    assert as_cuboids([message, box]) == (box, box)
    obstacle_set = inflarm_msgs_json.ObstacleSet('sra_mount', 0.01, (message,))
    assert as_cuboids(obstacle_set) == (box,)


@pytest.mark.parametrize(('args', 'match'), [
    (((0.2, 0, 0.6), (0.1, 0.1, 0.7)), r'min_corner <= max_corner.*x: 0\.2 > 0\.1'),
    (((0, 0, 0.6), (0.1, 0.1, float('nan'))), 'finite max_corner'),
    (((0, 0), (0.1, 0.1, 0.7)), r'min_corner of shape \(3,\)'),
    (((0, 0, 0.6), (0.1, 0.1, 0.7), 3), 'name to be a str'),
])
def test_cuboid_rejects_bad_corners_naming_them(args, match):
    with pytest.raises(ValueError, match=match):
        Cuboid(*args)


def test_bad_obstacles_and_margins_are_named():
    with pytest.raises(ValueError, match=r'obstacles\[1\] to be a Cuboid'):
        as_cuboids([BOX, (0, 0, 0)])
    with pytest.raises(ValueError, match='margin >= 0'):
        box_array([BOX], -0.01)
    with pytest.raises(ValueError, match='alert_margin >= 0'):
        BOX.grown(float('nan'))


# --- segments and the arm ----------------------------------------------------------------------


def test_segment_box_test_matches_dense_sampling():
    rng = np.random.default_rng(7)
    low, high = np.array([-0.05, 0.0, 0.6]), np.array([0.05, 0.1, 0.7])
    a = rng.uniform(-0.2, 0.2, (3000, 3)) + [0, 0, 0.65]
    b = rng.uniform(-0.2, 0.2, (3000, 3)) + [0, 0, 0.65]
    b[:500, 0] = a[:500, 0]  # parallel to the x slabs
    b[500:700] = a[500:700]  # points
    a[700:800, 0] = low[0]  # on a face, parallel to it
    b[700:800, 0] = low[0]
    hit = segments_hit_boxes(a, b, np.array([[low, high]]))
    reference = dense_segment_hits(a, b, low, high)
    assert hit.shape == (3000,)
    mismatch = np.flatnonzero(hit != reference)
    # sampling can only miss a grazing hit: every disagreement is a hit the samples stepped over
    assert np.all(hit[mismatch]), mismatch
    assert len(mismatch) <= 5
    assert 200 < hit.sum() < 2800


def test_arm_axes_are_those_of_the_model():
    rng = np.random.default_rng(7)
    ends = random_end_points(rng, 5000)
    boxes = box_array([BOX], 0.01)
    axes = central_axes(ends)
    expected = (segments_hit_boxes(axes[:, 0, 0], axes[:, 0, 1], boxes)
                | segments_hit_boxes(axes[:, 1, 0], axes[:, 1, 1], boxes))
    np.testing.assert_array_equal(arm_collides(ends, boxes), expected)
    contacts = arm_contacts(ends, boxes)
    np.testing.assert_array_equal(contacts.any, expected)
    np.testing.assert_array_equal(contacts.end, points_in_boxes(ends, boxes))
    assert np.all(contacts.pea2[contacts.end])


def test_arm_collides_agrees_with_an_independent_dense_check():
    rng = np.random.default_rng(7)
    ends = random_end_points(rng, 3000)
    low, high = BOX.grown(0.01).bounds
    expected = np.concatenate([
        strictly_inside(axis_points(ends[k:k + 200], 3000), low, high).any(axis=1)
        for k in range(0, len(ends), 200)])
    got = arm_collides(ends, box_array([BOX], 0.01))
    mismatch = np.flatnonzero(got != expected)
    assert np.all(got[mismatch]) and len(mismatch) <= 3  # only grazing hits between samples
    assert 0.05 < got.mean() < 0.5


def test_pea1_on_the_axis_is_tested_too():
    # a box around the z axis below the end: only PEA1 (and PEA2 above it) can meet it
    box = Cuboid((-0.01, -0.01, 0.2), (0.01, 0.01, 0.25))
    boxes = box_array([box])
    contacts = arm_contacts([[0.15, 0.0, 0.7], [0.0, 0.0, 0.8]], boxes)
    # l1 = (0.0225 + 0.49) / 1.4 = 0.366 m > 0.25 m: PEA1 passes through the box
    np.testing.assert_array_equal(contacts.pea1, [True, True])
    np.testing.assert_array_equal(contacts.end, [False, False])


def test_describe_collision_says_which_part_meets_which_box():
    named = Cuboid((0.035, 0.040, 0.650), (0.140, 0.140, 0.780), 'crate')
    assert describe_collision((0.0, 0.13, 0.71), [named], 0.01) is None
    assert "inside obstacle 0 'crate'" in describe_collision((0.1, 0.1, 0.7), [named], 0.01)
    text = describe_collision((0.03, 0.1, 0.7), [named], 0.01)
    assert text.startswith("the end is inside the alert region of obstacle 0 'crate'")
    # behind the box as seen from the PBA: only PEA2 crosses it
    assert describe_collision((0.17, 0.17, 0.72), [named], 0.01) == (
        "the PEA2 axis crosses the alert region of obstacle 0 'crate'")
    low = Cuboid((-0.02, -0.02, 0.30), (0.02, 0.02, 0.32))
    assert describe_collision((0.0, 0.0, 0.7), [BOX, low], 0.0) == (
        'the PEA1 axis crosses the alert region of obstacle 1')


def test_axes_move_no_farther_than_the_end_in_the_positive_workspace():
    # motions_collide's bound: |grad l1| = |(x/z, y/z, 1 - l1/z)| < 0.71 over the work space
    w = WORKSPACE_POSITIVE
    x, y, z = np.meshgrid(np.linspace(-w.x_max, w.x_max, 41), np.linspace(-w.y_max, w.y_max, 41),
                          np.linspace(w.z_min, w.z_max, 41), indexing='ij')
    l1 = (x * x + y * y + z * z) / (2 * z)
    gradient = np.sqrt((x / z) ** 2 + (y / z) ** 2 + (1 - l1 / z) ** 2)
    assert gradient.max() < 0.71
    # and numerically: axis points of two nearby poses are no farther apart than the ends
    rng = np.random.default_rng(7)
    a = random_end_points(rng, 2000)
    b = a + rng.normal(0.0, 0.002, a.shape)
    moved = np.linalg.norm(axis_points(a, 50) - axis_points(b, 50), axis=-1).max(axis=1)
    assert np.all(moved <= np.linalg.norm(b - a, axis=1) + 1e-12)


def test_motions_collide_tests_the_way_not_only_the_ends():
    boxes = box_array([BOX], 0.01)
    a, b = np.array([0.0, 0.13, 0.71]), np.array([0.13, 0.0, 0.73])
    assert not arm_collides(np.array([a, b]), boxes).any()
    assert motions_collide(a, b, boxes, 0.001)  # straight through the box
    around = np.array([0.02, 0.02, 0.72])
    assert not motions_collide(np.array([a, around]), np.array([around, b]), boxes, 0.001).any()
    # the end's path grazing a box corner between two samples is still found (exact slab test)
    corner = box_array([Cuboid((0.05, 0.05, 0.70), (0.06, 0.06, 0.71))])
    p, q = np.array([0.0495, 0.0605, 0.705]), np.array([0.0605, 0.0495, 0.705])
    assert not points_in_boxes(np.array([p, q]), corner).any()
    assert motions_collide(p, q, corner, 1.0)
    with pytest.raises(ValueError, match='step > 0'):
        motions_collide(a, b, boxes, 0.0)


# --- distances and the repulsive term ----------------------------------------------------------


def test_distance_to_boxes():
    boxes = box_array([BOX])
    points = np.array([[0.0, 0.13, 0.71], [0.1, 0.1, 0.7], [0.0, 0.0, 0.71], [0.2, 0.2, 0.8]])
    expected = [0.035, 0.0, np.hypot(0.035, 0.04), np.sqrt(0.06**2 + 0.06**2 + 0.02**2)]
    np.testing.assert_allclose(distance_to_boxes(points, boxes), expected, atol=1e-15)


def test_repulsive_offset_pushes_the_end_out_through_the_nearest_face():
    margin = 0.01
    offset = repulsive_offset([0.03, 0.1, 0.7], [BOX], margin)  # 5 mm into the -x side
    np.testing.assert_allclose(offset, [-0.005, 0.0, 0.0], atol=1e-12)
    offset = repulsive_offset([0.1, 0.145, 0.7], [BOX], margin)  # 5 mm into the +y side
    np.testing.assert_allclose(offset, [0.0, 0.005, 0.0], atol=1e-12)
    np.testing.assert_array_equal(repulsive_offset([0.0, 0.13, 0.71], [BOX], margin), 0.0)
    rng = np.random.default_rng(7)
    low, high = BOX.grown(margin).bounds
    points = rng.uniform(low, high, (1000, 3))
    offsets = repulsive_offset(points, [BOX], margin)
    moved = points + offsets
    # the offset is the shortest way out of the alert region: onto its surface, axis-aligned
    assert np.all(np.isclose(distance_to_boxes(moved, box_array([BOX], margin)), 0.0))
    assert not strictly_inside(moved, low, high).any()
    assert np.all(np.count_nonzero(offsets, axis=1) == 1)
    depth = np.minimum(points - low, high - points).min(axis=1)
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=1), depth, atol=1e-12)


def test_repulsive_offsets_of_overlapping_regions_add_up():
    boxes = [Cuboid((0.0, 0.0, 0.6), (0.05, 0.05, 0.7)), Cuboid((0.07, 0.0, 0.6),
                                                                   (0.1, 0.05, 0.7))]
    offset = repulsive_offset([0.06, 0.02, 0.65], boxes, 0.015)  # 5 mm into both
    np.testing.assert_allclose(offset, [0.005 - 0.005, 0.0, 0.0], atol=1e-12)
    offset = repulsive_offset([0.058, 0.02, 0.65], boxes, 0.015)
    np.testing.assert_allclose(offset, [0.007 - 0.003, 0.0, 0.0], atol=1e-12)
