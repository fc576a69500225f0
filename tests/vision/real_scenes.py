"""A yellow ball composited into real photographs, as a camera on a real rig would see it.

The photographs are the colour photographs and the photographic textures that ship inside
installed packages (nothing is downloaded), all free to use:

==================  =================  ========================================================
name                package            source and licence
==================  =================  ========================================================
astronaut           scikit-image       NASA portrait of Eileen Collins; public domain (NASA)
chelsea             scikit-image       a ginger cat on a wooden floor; CC0 (Stefan van der Walt)
coffee              scikit-image       a cup on a wooden table; CC0 (Rachel Michetti)
rocket              scikit-image       Falcon 9 launch (flame, sky, grass); public domain
                                       (SpaceX)
hubble              scikit-image       Hubble eXtreme Deep Field (small round yellow galaxies);
                                       public domain (NASA)
retina              scikit-image       fundus photograph (orange, red, round); CC0 (Mikael
                                       Haggstrom)
grace_hopper        matplotlib         portrait of Grace Hopper; public domain (US Navy)
grass               scikit-image       grass texture, tinted as foliage; CC0 (linolafett)
brick               scikit-image       brick wall texture, tinted brick red; CC0 (CC0Textures)
gravel              scikit-image       gravel texture, tinted as sand and wood; CC0
                                       (CC0Textures)
==================  =================  ========================================================

`real_case` crops and scales a photograph to a 640 x 480 frame and draws the ball on it: a
sphere of a yellow albedo (lemon to golden) lit by a key light from a random direction and an
ambient term, a specular highlight (a white spot that clips), coverage anti-aliased from 4 x 4
samples per pixel (a soft edge), optionally a bar of the arm's own parts over up to 30 % of its
outline; then defocus (Gaussian) or motion blur, exposure with clipping, sensor noise, and JPEG
(OpenCV's 4:2:0 chroma subsampling, as MJPEG cameras and image_transport's ``compressed``
transport deliver) at a given quality. The truth is the disc's centre and radius (OpenCV's
pixel-centre convention). `ball_free_frame` gives the same photographs without the ball.
Everything is deterministic for a seed.
"""

from dataclasses import dataclass
import functools
import math
from pathlib import Path

import cv2
import matplotlib
import numpy as np
import skimage

WIDTH, HEIGHT = 640, 480
_SKIMAGE = Path(skimage.__file__).parent / 'data'
_MATPLOTLIB = Path(matplotlib.get_data_path()) / 'sample_data'

# name -> (file, BGR tint for the grey textures or None)
PHOTOS = {
    'astronaut': (_SKIMAGE / 'astronaut.png', None),
    'chelsea': (_SKIMAGE / 'chelsea.png', None),
    'coffee': (_SKIMAGE / 'coffee.png', None),
    'rocket': (_SKIMAGE / 'rocket.jpg', None),
    'hubble': (_SKIMAGE / 'hubble_deep_field.jpg', None),
    'retina': (_SKIMAGE / 'retina.jpg', None),
    'grace_hopper': (_MATPLOTLIB / 'grace_hopper.jpg', None),
    'grass': (_SKIMAGE / 'grass.png', (0.35, 0.85, 0.45)),
    'brick': (_SKIMAGE / 'brick.png', (0.35, 0.45, 0.9)),
    'gravel': (_SKIMAGE / 'gravel.png', (0.45, 0.7, 0.9)),
}

JPEG_QUALITIES = (None, 95, 75, 50)  # None: no compression (PNG)


@functools.cache
def photo(name: str) -> np.ndarray:
    """The photograph as 8-bit BGR."""
    path, tint = PHOTOS[name]
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(path)
    if tint is not None:
        grey = image[:, :, 0].astype(np.float32)
        image = np.clip(grey[:, :, None] * np.array(tint, np.float32) * 1.1, 0, 255)
        image = image.astype(np.uint8)
    image.setflags(write=False)
    return image


@dataclass(frozen=True)
class Conditions:
    """How one frame was made."""

    photo: str
    radius_px: float
    exposure: float
    defocus_px: float  # Gaussian sigma, 0 for sharp
    motion_px: float  # length of a linear motion blur, 0 for none
    occlusion: float  # fraction of the outline under a bar of the arm, 0-0.3
    highlight: bool
    jpeg_quality: int | None


@dataclass(frozen=True)
class RealCase:
    image: np.ndarray
    center: np.ndarray  # (u, v) [px], OpenCV pixel-centre convention
    radius: float
    conditions: Conditions


def _frame(name: str, rng: np.random.Generator) -> np.ndarray:
    """A 640 x 480 crop of a photograph, scaled by 1-1.6 beyond what covers the frame."""
    image = photo(name)
    h, w = image.shape[:2]
    scale = max(WIDTH / w, HEIGHT / h) * rng.uniform(1.0, 1.6)
    size = (max(WIDTH, int(math.ceil(w * scale))), max(HEIGHT, int(math.ceil(h * scale))))
    big = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC)
    u0 = int(rng.integers(0, size[0] - WIDTH + 1))
    v0 = int(rng.integers(0, size[1] - HEIGHT + 1))
    frame = big[v0:v0 + HEIGHT, u0:u0 + WIDTH].astype(np.float32)
    return frame if rng.random() < 0.5 else frame[:, ::-1].copy()


def _draw_ball(frame: np.ndarray, center: np.ndarray, radius: float, rng: np.random.Generator,
               highlight: bool) -> None:
    """Shade a sphere's image onto ``frame`` (float BGR, in place), 4 x 4 samples a pixel."""
    albedo = np.array([rng.uniform(0.02, 0.25), rng.uniform(0.72, 0.9), rng.uniform(0.9, 1.0)])
    light = np.array([rng.normal(), rng.normal(), rng.uniform(0.4, 1.5)])
    light /= np.linalg.norm(light)
    ambient, key = rng.uniform(0.25, 0.45), rng.uniform(0.6, 0.85)
    half = np.array([light[0], light[1], light[2] + 1.0])
    half /= np.linalg.norm(half)
    shininess = rng.uniform(20.0, 80.0)
    u0, v0 = (int(math.floor(c - radius - 1)) for c in center)
    u1, v1 = (int(math.ceil(c + radius + 1)) + 1 for c in center)
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, WIDTH), min(v1, HEIGHT)
    offsets = (np.arange(4) + 0.5) / 4.0 - 0.5
    us = np.arange(u0, u1)[None, :, None, None] + offsets[None, None, None, :]
    vs = np.arange(v0, v1)[:, None, None, None] + offsets[None, None, :, None]
    x = (us - center[0]) / radius
    y = (vs - center[1]) / radius
    rho2 = x * x + y * y
    inside = rho2 < 1.0
    z = np.sqrt(np.maximum(1.0 - rho2, 0.0))
    # image axes: +u right, +v down; the normal's z points at the camera
    diffuse = np.maximum(x * light[0] + y * light[1] + z * light[2], 0.0)
    shade = ambient + key * diffuse
    colour = 255.0 * albedo[None, None, None, None, :] * shade[..., None]
    if highlight:
        spec = np.maximum(x * half[0] + y * half[1] + z * half[2], 0.0) ** shininess
        colour = colour + 255.0 * rng.uniform(0.7, 1.2) * spec[..., None]
    coverage = inside.mean(axis=(2, 3))
    ball = (colour * inside[..., None]).sum(axis=(2, 3)) / np.maximum(
        inside.sum(axis=(2, 3)), 1)[..., None]
    patch = frame[v0:v1, u0:u1]
    patch[:] = patch * (1.0 - coverage[..., None]) + ball * coverage[..., None]


def _draw_bar(frame: np.ndarray, center: np.ndarray, radius: float, occlusion: float,
              rng: np.random.Generator) -> None:
    """A straight bar of the arm (grey, dark or light) over ``occlusion`` of the outline: a
    band whose inner edge is the chord at ``r cos(pi occlusion)`` from the centre."""
    angle = rng.uniform(0.0, 2.0 * math.pi)
    normal = np.array([math.cos(angle), math.sin(angle)])
    inner = radius * math.cos(math.pi * occlusion)
    outer = inner + rng.uniform(0.8, 2.0) * radius + 6.0
    grey = rng.uniform(20.0, 230.0)
    colour = np.clip(grey + rng.normal(0.0, 8.0, 3), 0.0, 255.0)
    # anti-aliased band: coverage from the signed distance, 4 x 4 samples a pixel
    offsets = (np.arange(4) + 0.5) / 4.0 - 0.5
    reach = int(outer + radius + 4)
    u0, v0 = (max(int(c) - reach, 0) for c in center)
    u1, v1 = min(int(center[0]) + reach, WIDTH), min(int(center[1]) + reach, HEIGHT)
    us = np.arange(u0, u1)[None, :, None, None] + offsets[None, None, None, :]
    vs = np.arange(v0, v1)[:, None, None, None] + offsets[None, None, :, None]
    d = (us - center[0]) * normal[0] + (vs - center[1]) * normal[1]
    coverage = ((d > inner) & (d < outer)).mean(axis=(2, 3))[..., None]
    patch = frame[v0:v1, u0:u1]
    shading = 1.0 + 0.15 * np.tanh((d.mean(axis=(2, 3)) - inner) / (outer - inner) * 2 - 1)
    patch[:] = patch * (1.0 - coverage) + colour * shading[..., None] * coverage


def _finish(frame: np.ndarray, exposure: float, defocus: float, motion: float,
            jpeg_quality: int | None, rng: np.random.Generator) -> np.ndarray:
    """Blur, exposure, noise, 8 bits and JPEG."""
    if defocus > 0.0:
        frame = cv2.GaussianBlur(frame, (0, 0), defocus)
    if motion > 0.0:
        length = int(round(motion)) | 1
        kernel = np.zeros((length, length), np.float32)
        kernel[length // 2, :] = 1.0 / length
        rotation = cv2.getRotationMatrix2D((length // 2, length // 2),
                                           rng.uniform(0.0, 180.0), 1.0)
        kernel = cv2.warpAffine(kernel, rotation, (length, length))
        frame = cv2.filter2D(frame, -1, kernel / kernel.sum())
    frame = frame * exposure + rng.normal(0.0, rng.uniform(1.0, 3.0), frame.shape)
    image = np.clip(np.rint(frame), 0, 255).astype(np.uint8)
    if jpeg_quality is not None:
        ok, data = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        assert ok
        image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    return image


def random_conditions(rng: np.random.Generator, name: str,
                      radius_px: tuple[float, float] = (4.0, 150.0)) -> dict:
    """Conditions drawn at random (without the JPEG quality): radius log-uniform; half the
    frames blurred (defocus 0.8-2.5 px, or a 2-6 px motion), a third with a bar over 10-30 %
    of the outline, three quarters with a highlight."""
    blur = rng.random()
    return {
        'photo': name,
        'radius_px': float(math.exp(rng.uniform(*np.log(radius_px)))),
        'exposure': float(rng.uniform(0.5, 1.3)),
        'defocus_px': float(rng.uniform(0.8, 2.5)) if blur < 0.3 else 0.0,
        'motion_px': float(rng.uniform(2.0, 6.0)) if 0.3 <= blur < 0.5 else 0.0,
        'occlusion': float(rng.uniform(0.1, 0.3)) if rng.random() < 1 / 3 else 0.0,
        'highlight': bool(rng.random() < 0.75),
    }


def real_case(seed: int, jpeg_quality: int | None, **overrides) -> RealCase:
    """Frame ``seed`` of the set at one JPEG quality (the same scene for every quality).

    ``overrides`` replace drawn conditions (``radius_px``, ``occlusion``, ...)."""
    rng = np.random.default_rng(seed)
    names = sorted(PHOTOS)
    conditions = {**random_conditions(rng, names[seed % len(names)]), **overrides}
    frame = _frame(conditions['photo'], rng)
    radius = conditions['radius_px']
    margin = radius + 3.0
    center = np.array([rng.uniform(margin, WIDTH - margin), rng.uniform(margin, HEIGHT - margin)])
    # rendering draws: a separate stream, so the same scene comes at every quality
    draw = np.random.default_rng([seed, 1])
    _draw_ball(frame, center, radius, draw, conditions['highlight'])
    if conditions['occlusion'] > 0.0:
        _draw_bar(frame, center, radius, conditions['occlusion'], draw)
    image = _finish(frame, conditions['exposure'], conditions['defocus_px'],
                    conditions['motion_px'], jpeg_quality, draw)
    return RealCase(image, center, radius, Conditions(**conditions, jpeg_quality=jpeg_quality))


def ball_free_frame(seed: int, jpeg_quality: int | None) -> np.ndarray:
    """A crop of a photograph without the ball, with a random exposure and blur."""
    rng = np.random.default_rng([seed, 2])
    names = sorted(PHOTOS)
    frame = _frame(names[seed % len(names)], rng)
    defocus = float(rng.uniform(0.8, 2.5)) if rng.random() < 0.3 else 0.0
    return _finish(frame, float(rng.uniform(0.5, 1.3)), defocus, 0.0, jpeg_quality, rng)
