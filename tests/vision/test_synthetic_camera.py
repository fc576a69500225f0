"""inflarm_hw.synthetic_camera: the rendered ball is the exact sphere image, frames are
deterministic for a seed, and scene settings are validated."""

import numpy as np
import pytest

from inflarm_hw.synthetic_camera import BACKGROUNDS, Lighting, Scene, SyntheticCamera
from inflarm_model.camera import PinholeCamera, RigidTransform, look_at
from vision_scenes import CAMERA


@pytest.mark.parametrize('point', [[0.0, 0.0, 0.8], [0.2, -0.14, 0.7], [-0.05, 0.06, 0.35]])
def test_the_rendered_coverage_has_the_exact_area_and_centroid(point):
    flat = Scene(background='plain', background_bgr=(0.0, 0.0, 0.0), ball_bgr=(0.0, 0.0, 250.0),
                 lighting=Lighting(ambient=1.0, sky=0.0, key=0.0, specular=0.0), noise_std=0.0)
    camera = SyntheticCamera(CAMERA, RigidTransform.identity(), 0.02, flat)
    frame = camera.render(point)
    # red = 250 * coverage (to 1/500 per pixel: rounding)
    coverage = frame.image[:, :, 2].astype(float) / 250.0
    area = coverage.sum()
    v, u = np.mgrid[:CAMERA.height, :CAMERA.width]
    centroid = np.array([(coverage * u).sum(), (coverage * v).sum()]) / area
    truth = frame.truth
    assert np.sqrt(area / np.pi) == pytest.approx(truth.radius_px, abs=0.01)
    np.testing.assert_allclose(centroid, truth.center_px, atol=0.01)
    np.testing.assert_allclose(truth.position_camera, point)


def test_frames_are_deterministic_for_a_seed_and_differ_between_seeds():
    pose = look_at([0.0, -1.1, 0.78], [0.0, 0.0, 0.78])

    def frames(seed):
        camera = SyntheticCamera(CAMERA, pose, 0.02, Scene(background='clutter',
                                                           blur_sigma_px=0.7), seed=seed)
        return [camera.render([0.05, 0.02, 0.7]).image, camera.render(None).image]

    a, b, c = frames(3), frames(3), frames(4)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[1], c[1])
    assert not np.array_equal(a[0], a[1])


def test_the_ball_is_yellow_shaded_and_lit_from_above():
    camera = SyntheticCamera(CAMERA, look_at([0.0, -1.1, 0.78], [0.0, 0.0, 0.78]), 0.02,
                             Scene(noise_std=0.0))
    frame = camera.render([0.0, 0.0, 0.78])
    u, v = np.rint(frame.truth.center_px).astype(int)
    r = int(frame.truth.radius_px)
    top, bottom = frame.image[v - r + 3, u].astype(int), frame.image[v + r - 3, u].astype(int)
    for bgr in (top, bottom):
        assert bgr[2] > bgr[1] > 3 * bgr[0]  # red > green >> blue: yellow
    assert top.sum() > bottom.sum()  # sky light from the mount side (up in the image)


def test_exposure_saturates_and_backgrounds_differ():
    camera = SyntheticCamera(CAMERA, RigidTransform.identity(), 0.02, Scene(noise_std=0.0))
    bright = camera.render([0.0, 0.0, 0.5], exposure=3.0).image
    assert bright.max() == 255
    images = {kind: SyntheticCamera(CAMERA, scene=Scene(background=kind), seed=1).background
              for kind in BACKGROUNDS}
    assert np.ptp(images['plain'], axis=(0, 1)).max() == 0.0
    assert images['noise'].std(axis=(0, 1), dtype=float).min() > 10.0
    assert SyntheticCamera(CAMERA, scene=Scene(background='clutter'), seed=1).clutter_mask.any()


def test_invalid_settings_are_rejected():
    with pytest.raises(ValueError, match='background'):
        Scene(background='sky')
    with pytest.raises(ValueError, match='exposure'):
        Scene(exposure=0.0)
    with pytest.raises(ValueError, match='ball_radius'):
        SyntheticCamera(CAMERA, ball_radius=-1.0)
    with pytest.raises(ValueError, match='camera'):
        SyntheticCamera('camera')
    camera = SyntheticCamera(PinholeCamera.ideal(64, 48, 50.0))
    with pytest.raises(ValueError, match='outside the camera'):
        camera.render([0.0, 0.0, 0.01])
    with pytest.raises(ValueError, match='blur_sigma_px'):
        camera.render([0.0, 0.0, 1.0], blur_sigma_px=-1.0)
