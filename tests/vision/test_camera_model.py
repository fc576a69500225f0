"""inflarm_model.camera: projection with distortion, transforms, the exact image of a sphere."""

import math

import numpy as np
import pytest

from inflarm_model.camera import (
    PinholeCamera,
    RigidTransform,
    cone_rays,
    look_at,
    pixel_rays,
    project_points,
    sphere_image,
    undistort_pixels,
)

DISTORTED = PinholeCamera.ideal(640, 480, 900.0, d=[-0.12, 0.05, 0.001, -0.0008, 0.01])


def test_projection_and_undistortion_are_inverse_to_1e_9_px():
    rng = np.random.default_rng(7)
    pixels = rng.uniform([0.0, 0.0], [639.0, 479.0], size=(200, 2))
    rays = pixel_rays(DISTORTED, pixels)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0)
    np.testing.assert_allclose(project_points(DISTORTED, 2.5 * rays), pixels, atol=1e-9)
    xy = undistort_pixels(DISTORTED, pixels)
    corners = undistort_pixels(DISTORTED, [[0.0, 0.0], [639.0, 479.0]])
    # barrel distortion: the corners' rays are wider than the undistorted pinhole would give
    assert abs(corners[0, 0]) > 319.5 / 900.0
    assert xy.shape == (200, 2)


def test_rational_polynomial_model_and_camera_info_round_trip():
    camera = PinholeCamera(800, 600, np.array([[700.0, 0.0, 401.0], [0.0, 705.0, 299.0],
                                               [0.0, 0.0, 1.0]]),
                           np.array([0.1, -0.05, 0.0, 0.0, 0.01, 0.2, -0.1, 0.02]),
                           'rational_polynomial')
    fields = camera.camera_info_fields()
    assert fields['p'][:3] == [700.0, 0.0, 401.0] and fields['r'][0] == 1.0
    again = PinholeCamera.from_camera_info(fields['width'], fields['height'], fields['k'],
                                           fields['d'], fields['distortion_model'])
    np.testing.assert_array_equal(again.k, camera.k)
    np.testing.assert_array_equal(again.d, camera.d)
    point = np.array([0.2, -0.1, 1.3])
    np.testing.assert_allclose(pixel_rays(again, project_points(again, point)),
                               point / np.linalg.norm(point), atol=1e-12)
    # no distortion given at all (an empty CameraInfo.d)
    assert not PinholeCamera.from_camera_info(10, 10, fields['k'], [], '').d.any()


@pytest.mark.parametrize(('kwargs', 'match'), [
    ({'width': 0}, 'width'),
    ({'k': np.eye(3) * 0.0}, 'fx, fy > 0'),
    ({'d': [0.1, 0.2]}, 'expected d 5'),
    ({'distortion_model': 'equidistant'}, 'distortion_model'),
])
def test_invalid_intrinsics_are_rejected(kwargs, match):
    args = {'width': 640, 'height': 480, 'k': DISTORTED.k, 'd': DISTORTED.d,
            'distortion_model': 'plumb_bob'} | kwargs
    with pytest.raises(ValueError, match=match):
        PinholeCamera(**args)


def test_rigid_transforms_compose_invert_and_round_trip_quaternions():
    pose = look_at([0.3, -1.0, 0.5], [0.0, 0.0, 0.8])
    q = pose.as_quaternion()
    again = RigidTransform.from_quaternion(pose.translation, -2.0 * q)  # any scale and sign
    np.testing.assert_allclose(again.rotation, pose.rotation, atol=1e-12)
    p = np.array([[0.1, 0.2, 0.3], [-0.4, 0.0, 1.0]])
    np.testing.assert_allclose(pose.inverse().apply(pose.apply(p)), p, atol=1e-12)
    np.testing.assert_allclose((pose.inverse() @ pose).rotation, np.eye(3), atol=1e-12)
    # the target lies on the optical axis, the mount (-z) is up in the image
    target_cam = pose.inverse().apply([0.0, 0.0, 0.8])
    np.testing.assert_allclose(target_cam[:2], 0.0, atol=1e-12)
    above = pose.inverse().apply([0.0, 0.0, 0.7])
    assert above[1] < 0.0
    with pytest.raises(ValueError, match='quaternion'):
        RigidTransform.from_quaternion([0, 0, 0], [0, 0, 0, 0])
    with pytest.raises(ValueError, match='proper rotation'):
        RigidTransform(np.diag([1.0, 1.0, -1.0]), np.zeros(3))


def test_a_sphere_on_the_axis_images_as_a_circle_of_radius_f_tan_a():
    camera = PinholeCamera.ideal(640, 480, 900.0)
    radius, distance = 0.02, 0.6
    image = sphere_image(camera, [0.0, 0.0, distance], radius)
    expected = 900.0 * math.tan(math.asin(radius / distance))
    assert image.radius == pytest.approx(expected, abs=1e-4)
    np.testing.assert_allclose(image.center, [319.5, 239.5], atol=1e-9)
    # D = R sqrt(f^2 + r^2) / r, not f R / r
    r = image.radius
    assert radius * math.sqrt(900.0 ** 2 + r * r) / r == pytest.approx(distance, rel=1e-5)
    assert 900.0 * radius / r == pytest.approx(distance * math.cos(math.asin(radius / distance)),
                                               rel=1e-5)


def test_off_axis_the_image_centre_is_not_the_projected_centre():
    camera = PinholeCamera.ideal(640, 480, 900.0)
    center = np.array([0.12, 0.08, 0.6])
    image = sphere_image(camera, center, 0.04)
    # every outline ray is tangent to the sphere
    rays = cone_rays(center, 0.04, 64)
    cos_a = math.sqrt(1.0 - (0.04 / np.linalg.norm(center)) ** 2)
    np.testing.assert_allclose(rays @ center / np.linalg.norm(center), cos_a, atol=1e-12)
    offset = image.center - image.projected_center
    assert np.linalg.norm(offset) > 0.5  # pixels: far above detection accuracy
    # the ellipse's centre lies further out, along the radial direction
    radial = image.projected_center - [319.5, 239.5]
    assert offset @ radial > 0.99 * np.linalg.norm(offset) * np.linalg.norm(radial)
    assert image.inside_image(camera)
    assert not sphere_image(camera, [0.35, 0.0, 0.6], 0.03).inside_image(camera)
