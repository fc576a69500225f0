"""Seeded synthetic scenes shared by the vision tests: the simulated camera of sra_sim and a set
of balls over positions, sizes, blur, noise, exposure and lighting."""

from dataclasses import dataclass

import numpy as np

from inflarm_hw.synthetic_camera import Lighting, Scene, SyntheticCamera, SyntheticFrame
from inflarm_model.camera import PinholeCamera, RigidTransform

# The default camera of sra_sim: 640x480, f = 900 px, barrel distortion.
CAMERA = PinholeCamera.ideal(640, 480, 900.0, d=[-0.12, 0.05, 0.0005, -0.0003, 0.0])
BALL_RADIUS = 0.02  # [m]


@dataclass(frozen=True)
class Case:
    frame: SyntheticFrame
    blur: float
    noise: float
    exposure: float
    background: str


def random_case(rng: np.random.Generator, background: str, distance: float | None = None,
                radius_px: tuple[float, float] = (5.0, 40.0), max_blur: float = 1.5,
                seed: int = 0) -> Case:
    """A ball fully in view in the camera frame (``camera2world`` the identity): at
    ``distance`` [m] if given, else at the distance giving an apparent radius drawn from
    ``radius_px``; light from a random direction; blur, noise and exposure drawn at random."""
    if distance is None:
        distance = CAMERA.focal_px * BALL_RADIUS / rng.uniform(*radius_px)
    blur = rng.uniform(0.0, max_blur)
    noise = rng.uniform(0.5, 3.0)
    exposure = rng.uniform(0.6, 1.5)
    lighting = Lighting(key_direction=tuple(rng.normal(size=3)), up=(0.0, -1.0, 0.0))
    camera = SyntheticCamera(CAMERA, RigidTransform.identity(), BALL_RADIUS,
                             Scene(background=background, lighting=lighting, blur_sigma_px=blur,
                                   noise_std=noise, exposure=exposure), seed=seed)
    for _ in range(100):
        # a direction within the field of view, the whole ball inside the image
        direction = np.array([rng.uniform(-0.33, 0.33), rng.uniform(-0.25, 0.25), 1.0])
        point = distance * direction / np.linalg.norm(direction)
        truth = camera.ball_truth(point)
        if truth.image.inside_image(CAMERA, margin=3.0) and (
                background != 'clutter' or clear_of_clutter(camera, truth)):
            return Case(camera.render(point), blur, noise, exposure, background)
    raise RuntimeError('no free position for the ball')


def clear_of_clutter(camera: SyntheticCamera, truth, margin_px: float = 4.0) -> bool:
    """Whether no yellow clutter shape comes within ``margin_px`` of the ball's outline."""
    c = truth.image.center
    reach = truth.image.radius * 1.3 + margin_px
    u0, v0 = int(max(c[0] - reach, 0)), int(max(c[1] - reach, 0))
    u1, v1 = int(min(c[0] + reach + 1, CAMERA.width)), int(min(c[1] + reach + 1, CAMERA.height))
    return not camera.clutter_mask[v0:v1, u0:u1].any()
