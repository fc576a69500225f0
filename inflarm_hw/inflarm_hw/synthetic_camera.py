"""Synthetic camera: images of a shaded yellow ball through a pinhole camera with distortion.

The simulated stand-in for the external camera of ``001_b59ad71c956a1751`` (3.3, 4.3.2), which
records a small yellow ball on the soft arm's end. It renders the exact perspective image of the
sphere (the outline of its tangent cone, `inflarm_model.camera.sphere_image`, lens distortion
included) with anti-aliased coverage, shades it (ambient, sky and key light, specular
highlight), composites it over a background (plain, textured noise, or clutter with other
yellow-ish shapes), then applies blur, exposure (with saturation) and sensor noise, and returns
the 8-bit BGR image with the exact ground truth. Pure numpy/OpenCV, no rclpy; deterministic for
a seed.

Image formation, in linear grey levels (0-255 at exposure 1, no gamma)::

    coverage c(pixel)   fraction of the pixel whose rays hit the sphere (16 x 16 sub-pixel
                        rays tested against the tangent cone, distortion included:
                        `inflarm_model.camera.sphere_coverage`)
    colour              background (1 - c) + c (albedo shade + 255 specular)
    image               clip(exposure * blur(colour) + noise, 0, 255), rounded to uint8

Shading at the surface point seen through the pixel's centre (normal ``n``, towards the light
``l``, ``up`` and the viewer ``v``, all in the camera frame)::

    shade = ambient + sky (1 + n.up) / 2 + key max(0, n.l);  specular = s max(0, n.h)^shininess
"""

from dataclasses import dataclass, field
import math

import cv2
import numpy as np
import numpy.typing as npt

from inflarm_model.camera import (
    PinholeCamera,
    RigidTransform,
    SphereImage,
    sphere_coverage,
    sphere_image,
)

__all__ = [
    'BACKGROUNDS',
    'BallTruth',
    'Lighting',
    'Scene',
    'SraCamera',
    'SyntheticCamera',
    'SyntheticFrame',
]

BACKGROUNDS = ('plain', 'noise', 'clutter')
_SUPERSAMPLING = 16


def _unit(vector: npt.ArrayLike, name: str) -> npt.NDArray[np.float64]:
    v = np.asarray(vector, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        raise ValueError(f'expected {name} a finite non-zero (3,) vector, got {v}')
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class Lighting:
    """Light on the ball, directions in the world frame (that of ``camera2world``).

    Attributes
    ----------
    ambient : float
        Uniform light [fraction of the albedo].
    sky : float
        Hemisphere light from ``up``: ``sky (1 + n.up) / 2``.
    key : float
        Directional light towards ``key_direction``: ``key max(0, n.l)``.
    key_direction : tuple of 3 float
        Direction towards the key light (normalized).
    up : tuple of 3 float
        Up in the world (default ``-z``: towards the mount in ``sra_mount``).
    specular : float
        Peak of the white Blinn-Phong highlight [fraction of 255].
    shininess : float
        Blinn-Phong exponent.
    """

    ambient: float = 0.35
    sky: float = 0.35
    key: float = 0.4
    key_direction: tuple[float, float, float] = (0.4, -0.6, -0.7)
    up: tuple[float, float, float] = (0.0, 0.0, -1.0)
    specular: float = 0.25
    shininess: float = 30.0

    def __post_init__(self) -> None:
        for name in ('ambient', 'sky', 'key', 'specular', 'shininess'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f'expected {name} >= 0, got {value}')
        _unit(self.key_direction, 'key_direction')
        _unit(self.up, 'up')


@dataclass(frozen=True)
class Scene:
    """What the synthetic camera sees besides the ball, and how it records it.

    Attributes
    ----------
    background : str
        ``'plain'`` (uniform ``background_bgr``), ``'noise'`` (smooth grey texture with fine
        grain around ``background_bgr``) or ``'clutter'`` (the noise texture with
        ``clutter_count`` yellow-ish shapes: same-hue rectangles, bars, triangles, rings,
        elongated ellipses and half discs; orange, lime and pale-yellow discs).
    background_bgr : tuple of 3 float
        Mean background colour [grey levels, 0-255].
    clutter_count : int
        Number of clutter shapes.
    ball_bgr : tuple of 3 float
        Albedo of the ball, the colour of a fully lit point at exposure 1 [grey levels]: yellow.
    lighting : Lighting
    blur_sigma_px : float
        Standard deviation of the Gaussian blur (defocus, motion) [px].
    noise_std : float
        Standard deviation of the sensor noise [grey levels].
    exposure : float
        Gain on the scene before clipping to 255 (1: nominal).
    """

    background: str = 'plain'
    background_bgr: tuple[float, float, float] = (115.0, 120.0, 125.0)
    clutter_count: int = 14
    ball_bgr: tuple[float, float, float] = (25.0, 200.0, 240.0)
    lighting: Lighting = field(default_factory=Lighting)
    blur_sigma_px: float = 0.0
    noise_std: float = 1.5
    exposure: float = 1.0

    def __post_init__(self) -> None:
        if self.background not in BACKGROUNDS:
            raise ValueError(f'background: expected one of {BACKGROUNDS}, got {self.background!r}')
        for name in ('background_bgr', 'ball_bgr'):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all((value >= 0.0) & (value <= 255.0)):
                raise ValueError(f'expected {name} 3 values in [0, 255], got {value}')
        if isinstance(self.clutter_count, bool) or not isinstance(self.clutter_count, int) \
                or self.clutter_count < 0:
            raise ValueError(f'expected clutter_count an integer >= 0, got {self.clutter_count!r}')
        for name in ('blur_sigma_px', 'noise_std'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f'expected {name} >= 0, got {value}')
        if not (np.isfinite(self.exposure) and self.exposure > 0.0):
            raise ValueError(f'expected exposure > 0, got {self.exposure}')


@dataclass(frozen=True)
class BallTruth:
    """Exact ground truth of the ball in one frame.

    Attributes
    ----------
    position_camera : ndarray, shape (3,)
        Ball centre in the camera frame [m].
    position_world : ndarray, shape (3,)
        Ball centre in the world frame [m] (as passed to `SyntheticCamera.render`).
    image : SphereImage
        Its exact image: outline, centre (centroid) and apparent radius [px], and the
        projection of the centre.
    in_view : bool
        Whether the whole outline lies inside the image.
    """

    position_camera: npt.NDArray[np.float64]
    position_world: npt.NDArray[np.float64]
    image: SphereImage
    in_view: bool

    @property
    def center_px(self) -> npt.NDArray[np.float64]:
        """Centre of the sphere's image [px] (``image.center``)."""
        return self.image.center

    @property
    def radius_px(self) -> float:
        """Apparent radius [px] (``image.radius``)."""
        return self.image.radius


@dataclass(frozen=True)
class SyntheticFrame:
    """One rendered frame.

    Attributes
    ----------
    image : ndarray, shape (height, width, 3), uint8
        BGR image.
    truth : BallTruth or None
        None when no ball was rendered.
    """

    image: npt.NDArray[np.uint8]
    truth: BallTruth | None


class SyntheticCamera:
    """Renders a yellow ball at 3D points, seen by a camera at a fixed pose.

    Parameters
    ----------
    camera : PinholeCamera
        Intrinsics, distortion included.
    camera2world : RigidTransform
        Pose of the camera in the world frame (``sra_mount`` in the simulation).
    ball_radius : float
        Radius of the ball [m].
    scene : Scene
        Background, lighting, blur, noise and exposure.
    seed : int
        Seed of the background texture, the clutter and the noise sequence.
    """

    def __init__(self, camera: PinholeCamera,
                 camera2world: RigidTransform = RigidTransform.identity(),  # noqa: B008 (frozen)
                 ball_radius: float = 0.02,
                 scene: Scene = Scene(),  # noqa: B008 (frozen)
                 seed: int = 0) -> None:
        if not isinstance(camera, PinholeCamera):
            raise ValueError(f'expected camera a PinholeCamera, got {type(camera).__name__}')
        if not isinstance(camera2world, RigidTransform):
            raise ValueError(
                f'expected camera2world a RigidTransform, got {type(camera2world).__name__}')
        if not (np.isfinite(ball_radius) and ball_radius > 0.0):
            raise ValueError(f'expected ball_radius > 0 [m], got {ball_radius}')
        if not isinstance(scene, Scene):
            raise ValueError(f'expected scene a Scene, got {type(scene).__name__}')
        self.camera = camera
        self.camera2world = camera2world
        self.world2camera = camera2world.inverse()
        self.ball_radius = float(ball_radius)
        self.scene = scene
        self.rng = np.random.default_rng(seed)
        world_to_camera = camera2world.rotation.T
        light = scene.lighting
        self._up = world_to_camera @ _unit(light.up, 'up')
        self._key = world_to_camera @ _unit(light.key_direction, 'key_direction')
        self.clutter_mask = np.zeros((camera.height, camera.width), dtype=bool)
        self.background = self._make_background()
        self.background.setflags(write=False)
        self.clutter_mask.setflags(write=False)

    # -- background ----------------------------------------------------------------------------

    def _make_background(self) -> npt.NDArray[np.float32]:
        h, w = self.camera.height, self.camera.width
        base = np.asarray(self.scene.background_bgr, dtype=np.float32)
        image = np.empty((h, w, 3), dtype=np.float32)
        image[:] = base
        if self.scene.background == 'plain':
            return image
        rng = self.rng
        # smooth luminance texture (features ~ 1/16 of the image), faint chroma, fine grain
        coarse = rng.standard_normal((max(2, h // 16), max(2, w // 16), 1)).astype(np.float32)
        smooth = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)[:, :, None]
        chroma = rng.standard_normal((max(2, h // 32), max(2, w // 32), 3)).astype(np.float32)
        chroma = cv2.resize(chroma, (w, h), interpolation=cv2.INTER_CUBIC)
        grain = rng.standard_normal((h, w, 1)).astype(np.float32)
        image += 30.0 * smooth + 6.0 * chroma + 6.0 * grain
        np.clip(image, 5.0, 250.0, out=image)
        if self.scene.background == 'clutter':
            self._draw_clutter(image)
        return image

    def _draw_clutter(self, image: npt.NDArray[np.float32]) -> None:
        """Yellow-ish shapes that are not a yellow ball: same-hue non-round shapes, round shapes
        of other hues or saturations."""
        rng = self.rng
        h, w = image.shape[:2]
        yellow = np.asarray(self.scene.ball_bgr)
        others = {'orange_disc': (10.0, 80.0, 230.0), 'lime_disc': (40.0, 230.0, 120.0),
                  'pale_disc': (155.0, 210.0, 225.0)}
        kinds = ('rectangle', 'bar', 'triangle', 'ring', 'ellipse', 'half_disc',
                 'orange_disc', 'lime_disc', 'pale_disc')
        shift = 4  # sub-pixel vertex precision, 1/16 px
        scale = 1 << shift
        for _ in range(self.scene.clutter_count):
            kind = kinds[rng.integers(len(kinds))]
            colour = np.asarray(others.get(kind, yellow)) * rng.uniform(0.7, 1.15)
            colour = tuple(float(c) for c in np.clip(colour, 0.0, 255.0))
            size = rng.uniform(8.0, 0.12 * min(h, w) + 10.0)
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
            angle = rng.uniform(0.0, 180.0)
            layer = np.zeros((h, w), dtype=np.uint8)
            center = (int(cx * scale), int(cy * scale))
            if kind == 'rectangle':
                box = cv2.boxPoints(((cx, cy), (size, size * rng.uniform(1.3, 4.0)), angle))
                cv2.fillPoly(layer, [np.round(box * scale).astype(np.int32)], 255, cv2.LINE_AA,
                             shift)
            elif kind == 'bar':
                length = size * rng.uniform(2.0, 5.0)
                dx, dy = 0.5 * length * math.cos(math.radians(angle)), \
                    0.5 * length * math.sin(math.radians(angle))
                cv2.line(layer, (int((cx - dx) * scale), int((cy - dy) * scale)),
                         (int((cx + dx) * scale), int((cy + dy) * scale)), 255,
                         int(rng.integers(3, 11)), cv2.LINE_AA, shift)
            elif kind == 'triangle':
                corners = np.array([[cx + size * math.cos(math.radians(angle + k * 120.0)),
                                     cy + size * math.sin(math.radians(angle + k * 120.0))]
                                    for k in range(3)])
                cv2.fillPoly(layer, [np.round(corners * scale).astype(np.int32)], 255,
                             cv2.LINE_AA, shift)
            elif kind == 'ring':
                cv2.circle(layer, center, int(size * scale), 255,
                           max(2, int(size * rng.uniform(0.1, 0.3))), cv2.LINE_AA, shift)
            elif kind == 'ellipse':
                axes = (int(size * scale), int(size * rng.uniform(0.2, 0.55) * scale))
                cv2.ellipse(layer, center, axes, angle, 0.0, 360.0, 255, -1, cv2.LINE_AA, shift)
            elif kind == 'half_disc':
                axes = (int(size * scale), int(size * scale))
                cv2.ellipse(layer, center, axes, angle, 0.0, 180.0, 255, -1, cv2.LINE_AA, shift)
            else:  # discs of other hues
                cv2.circle(layer, center, int(size * scale), 255, -1, cv2.LINE_AA, shift)
            x, y, bw, bh = cv2.boundingRect(layer)  # composite only where the shape is
            if bw == 0 or bh == 0:
                continue
            box = (slice(y, y + bh), slice(x, x + bw))
            alpha = layer[box].astype(np.float32)[:, :, None] * (1.0 / 255.0)
            image[box] += alpha * (np.asarray(colour, dtype=np.float32) - image[box])
            if kind not in others:
                self.clutter_mask[box] |= layer[box] > 0

    # -- frames --------------------------------------------------------------------------------

    def ball_truth(self, position_world: npt.ArrayLike) -> BallTruth:
        """Ground truth of the ball at a point, without rendering (see `BallTruth`)."""
        p_world = np.asarray(position_world, dtype=float)
        if p_world.shape != (3,) or not np.all(np.isfinite(p_world)):
            raise ValueError(f'expected position_world a finite (3,) point [m], got {p_world}')
        p_cam = self.world2camera.apply(p_world)
        if np.linalg.norm(p_cam) <= self.ball_radius:
            raise ValueError('expected the ball outside the camera (|position| > ball radius)')
        image = sphere_image(self.camera, p_cam, self.ball_radius)
        return BallTruth(position_camera=p_cam, position_world=p_world, image=image,
                         in_view=image.inside_image(self.camera))

    def render(self, position_world: npt.ArrayLike | None, exposure: float | None = None,
               blur_sigma_px: float | None = None) -> SyntheticFrame:
        """Render one frame.

        Parameters
        ----------
        position_world : array-like, shape (3,), or None
            Ball centre in the world frame [m]; None renders the background alone.
        exposure, blur_sigma_px : float, optional
            Override the scene's values for this frame.

        Returns
        -------
        SyntheticFrame
            The image and the ball's ground truth (None without a ball). Each call draws new
            sensor noise from the camera's generator.
        """
        exposure = self.scene.exposure if exposure is None else float(exposure)
        blur = self.scene.blur_sigma_px if blur_sigma_px is None else float(blur_sigma_px)
        if not (np.isfinite(exposure) and exposure > 0.0):
            raise ValueError(f'expected exposure > 0, got {exposure}')
        if not (np.isfinite(blur) and blur >= 0.0):
            raise ValueError(f'expected blur_sigma_px >= 0, got {blur}')
        colour = self.background.copy()
        truth = None
        if position_world is not None:
            truth = self.ball_truth(position_world)
            self._draw_ball(colour, truth)
        if blur > 0.0:
            colour = cv2.GaussianBlur(colour, (0, 0), blur, borderType=cv2.BORDER_REFLECT)
        colour *= exposure
        if self.scene.noise_std > 0.0:
            # OpenCV's generator (twice as fast as numpy's here), seeded from the camera's own
            # generator for every frame: the sequence stays deterministic for a seed
            noise = np.empty(colour.shape[:2] + (3,), dtype=np.float32)
            cv2.setRNGSeed(int(self.rng.integers(2**31 - 1)))
            cv2.randn(noise.reshape(noise.shape[0], -1), 0.0, self.scene.noise_std)
            colour += noise
        np.maximum(colour, 0.0, out=colour)
        # rounds to nearest and saturates at 255
        image = cv2.convertScaleAbs(colour)
        return SyntheticFrame(image=image, truth=truth)

    def _draw_ball(self, colour: npt.NDArray[np.float32], truth: BallTruth) -> None:
        center = truth.position_camera
        covered = sphere_coverage(self.camera, center, self.ball_radius, _SUPERSAMPLING)
        if covered is None or not covered.coverage.any():
            return  # entirely outside the image
        h, w = covered.coverage.shape
        rays = np.concatenate([covered.undistorted, np.ones((h, w, 1))], axis=-1)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        ball = self._shade(rays, center)
        roi = colour[covered.v0:covered.v0 + h, covered.u0:covered.u0 + w]
        roi += covered.coverage[:, :, None] * (ball - roi)

    def _shade(self, rays: npt.NDArray[np.float64],
               center: npt.NDArray[np.float64]) -> npt.NDArray[np.float32]:
        """BGR colour of the ball surface seen along unit ``rays`` (..., 3)."""
        # ray-sphere intersection; rays that just miss (edge pixels) take the tangent point
        b = rays @ center
        disc = np.maximum(b * b - (center @ center - self.ball_radius ** 2), 0.0)
        point = (b - np.sqrt(disc))[..., None] * rays
        normal = (point - center) / self.ball_radius
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        light = self.scene.lighting
        shade = (light.ambient + light.sky * 0.5 * (1.0 + normal @ self._up)
                 + light.key * np.maximum(normal @ self._key, 0.0))
        half = self._key - rays
        half /= np.linalg.norm(half, axis=-1, keepdims=True)
        lit = (normal @ self._key) > 0.0
        specular = np.where(lit, light.specular
                            * np.maximum((normal * half).sum(-1), 0.0) ** light.shininess, 0.0)
        albedo = np.asarray(self.scene.ball_bgr, dtype=float)
        return (shade[..., None] * albedo + 255.0 * specular[..., None]).astype(np.float32)


@dataclass(frozen=True)
class SraCamera:
    """The soft arm's simulated external camera: the one definition of its defaults.

    ``sra_sim`` and ``sim_mcu`` declare their ``camera.*`` parameters with these defaults
    (``inflarm_hw.nodes.camera_publisher``), and tools that close the loop through the camera
    without ROS render with `renderer` (``inflarm-sra-experiments --camera``).

    Attributes
    ----------
    width, height : int
        Image size [px].
    focal_px : float
        Focal length, square pixels, principal point at the image centre [px].
    distortion : tuple of 5 float
        plumb_bob k1, k2, p1, p2, k3.
    translation_m : tuple of 3 float
        Camera (optical frame) origin in ``sra_mount`` [m].
    rotation_xyzw : tuple of 4 float
        Camera -> mount rotation, quaternion. With ``translation_m`` the defaults are
        ``look_at([0, -1.1, 0.78], [0, 0, 0.78])``: 1.1 m from the arm's axis on -y, level with
        the middle of the work space, looking along +y.
    ball_diameter_m : float
        Diameter of the yellow ball [m] (the paper gives none: a 40 mm table-tennis ball).
    background : str
        One of `BACKGROUNDS`.
    noise_std, blur_sigma_px, exposure : float
        Sensor noise [grey levels], blur [px] and exposure gain (`Scene`).
    latency_s : float
        Delay from capture to publication [s] (the nodes' publisher; `renderer` ignores it).
    """

    width: int = 640
    height: int = 480
    focal_px: float = 900.0
    distortion: tuple[float, ...] = (-0.12, 0.05, 0.0, 0.0, 0.0)
    translation_m: tuple[float, float, float] = (0.0, -1.1, 0.78)
    rotation_xyzw: tuple[float, float, float, float] = (0.0, 0.70710678, 0.70710678, 0.0)
    ball_diameter_m: float = 0.04
    background: str = 'noise'
    noise_std: float = 1.5
    blur_sigma_px: float = 0.5
    exposure: float = 1.0
    latency_s: float = 0.03

    def camera(self) -> PinholeCamera:
        """The intrinsics (`PinholeCamera.ideal`); ``ValueError`` on bad ones."""
        return PinholeCamera.ideal(self.width, self.height, self.focal_px, d=self.distortion)

    def camera2mount(self) -> RigidTransform:
        """The camera's pose in ``sra_mount``; ``ValueError`` on a bad quaternion."""
        return RigidTransform.from_quaternion(self.translation_m, self.rotation_xyzw)

    def renderer(self, seed: int | None = None) -> 'SyntheticCamera':
        """The `SyntheticCamera` of this set-up, seeded (None: a random seed).

        Raises
        ------
        ValueError
            Naming the value that is wrong.
        """
        scene = Scene(background=self.background, noise_std=self.noise_std,
                      blur_sigma_px=self.blur_sigma_px, exposure=self.exposure)
        if not (math.isfinite(self.ball_diameter_m) and self.ball_diameter_m > 0.0):
            raise ValueError(f'expected ball_diameter_m > 0 [m], got {self.ball_diameter_m}')
        return SyntheticCamera(self.camera(), self.camera2mount(), 0.5 * self.ball_diameter_m,
                               scene, seed=seed)
