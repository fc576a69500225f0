"""Detection and tracking of a yellow ball in BGR images, with a sub-pixel outline.

The vision sensor of ``001_b59ad71c956a1751`` (3.1, 3.3, 4.3.2): an external camera records the
small yellow ball on the soft arm's end. Pure numpy/OpenCV, no rclpy.

Pipeline of `detect_ball` (one frame, whole image):

1. **Candidates** on a copy shrunk by ``s`` (`DetectorParams.decimation`: the smallest ball
   keeps >= 2 px of radius): HSV thresholds (``cv2.inRange``), an opening that removes specks,
   external contours with their holes (``cv2.findContours``, two-level hierarchy). A contour is
   a candidate if its area fits the radius range, its circularity ``4 pi A / P^2`` and its
   fill (area not in holes) are high enough, and it lies close to an ellipse that is not too
   elongated (`_elliptic`).
2. **Sub-pixel outline** (`_refine_at`), from the candidate's centroid and area: rays sample
   the full-resolution image (bilinear, ``cv2.remap``) across the ball's edge, and on each ray
   the edge is where the signal crosses half-way between the inside and outside levels
   (`_edges`). The signal is a colour channel **blind to the ball's colour** (orthogonal in
   BGR to the ball's colour, measured on its unclipped, unhighlighted pixels): in it the ball
   reads 0 however it is shaded, and the edge is the background being covered, so limb
   darkening and shadow do not move it. When the background is itself dark in that channel
   (black, red, yellow surroundings) the **chroma** channel (orthogonal to grey) is used. The
   edge points are moved out by the blur's shift of a curved edge, ``sigma^2 / (2 r)``.
3. **Fit** (`_fit_outline`): an ellipse (``cv2.fitEllipseDirect``) through the edge points,
   refitted without those farther from it than 3 robust standard deviations (at most
   ``0.5 + 0.03 r`` px). ``confidence`` is the fraction of rays whose edge lies on the
   ellipse; a candidate is accepted (`_accept`) if it is high enough, the ellipse not too
   elongated and its radius in range. If the outline from the decimated candidate fails, its
   blob is thresholded again at full resolution in a region around it (`refine_in_region`).
   The accepted candidate of highest confidence wins.

`BallTracker` refines the outline at the position predicted from the last detections with
their colour and blur (tracking mode), then tries the thresholded blobs around it, and falls
back to `detect_ball` on the whole frame when the ball is lost.

Pixel convention (OpenCV's): pixel ``i`` spans ``[i - 0.5, i + 0.5]``; ``center`` is the centre
of the fitted ellipse, ``radius`` ``sqrt(a b)`` of its semi-axes (the radius of the disc of equal
area). For the ball's 3D position use the edge points (`inflarm_vision.geometry.locate_ball`):
off the optical axis the ellipse's centre is not the image of the ball's centre.
"""

from dataclasses import dataclass
import functools
import math

import cv2
import numpy as np
import numpy.typing as npt

__all__ = [
    'BallDetection',
    'BallTracker',
    'DetectorParams',
    'detect_ball',
    'refine_in_region',
]


def _check_hsv(value, name: str) -> tuple[int, int, int]:
    v = tuple(value)
    if len(v) != 3 or not all(isinstance(x, (int, np.integer)) and not isinstance(x, bool)
                              for x in v):
        raise ValueError(f'expected {name} 3 integers (H, S, V), got {value!r}')
    limits = (180, 255, 255)
    if any(x < 0 or x > lim for x, lim in zip(v, limits, strict=True)):
        raise ValueError(f'expected {name} within H 0-180, S 0-255, V 0-255, got {v}')
    return tuple(int(x) for x in v)


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of the detector, validated on construction (``ValueError`` naming the field).

    Attributes
    ----------
    hsv_lower, hsv_upper : tuple of 3 int
        Inclusive HSV thresholds in OpenCV's ranges (H 0-180, S and V 0-255). The defaults take
        a yellow ball (hue 17-38, i.e. 34-76 deg) under indoor light from exposure 0.5 to 1.7:
        dark limbs (V >= 45) and highlights where red and green clip (hue -> 30). Orange (hue
        about 10) and lime (about 47) are out, so are pale yellows and dark browns (S < 130:
        a yellow ball's saturation, about 0.9, does not change with its shading).
    min_radius_px, max_radius_px : float
        Range of apparent radii [px].
    min_circularity : float
        Smallest ``4 pi A / P^2`` of a candidate's thresholded contour (1 for a disc, pi / 4
        for a square, 0.75 for a half disc; a pixel contour scores less than its shape).
    min_fill : float
        Smallest fraction of a candidate's contour area that is not holes (rejects rings; a
        highlight the thresholds miss is a small hole).
    max_aspect_ratio : float
        Largest ratio of the fitted ellipse's axes. The image of a sphere at angle ``t`` off the
        optical axis has a ratio of about ``1 / cos(t)``: 1.15 at 30 deg, 1.31 at 40 deg.
    min_confidence : float
        Smallest fraction of the outline found on the fitted ellipse (a half disc scores about
        0.7).
    min_chroma : float
        Smallest distance of the ball's colour from grey [grey levels] (rejects dark, nearly
        grey blobs whose hue is noise).
    opening_px : int
        Size of the square structuring element of the opening on the decimated mask (0: none).
    max_candidates : int
        Number of candidates refined per frame, best first.
    """

    hsv_lower: tuple[int, int, int] = (17, 130, 45)
    hsv_upper: tuple[int, int, int] = (38, 255, 255)
    min_radius_px: float = 4.0
    max_radius_px: float = 150.0
    min_circularity: float = 0.6
    min_fill: float = 0.85
    max_aspect_ratio: float = 1.3
    min_confidence: float = 0.8
    min_chroma: float = 20.0
    opening_px: int = 3
    max_candidates: int = 4

    def __post_init__(self) -> None:
        lower = _check_hsv(self.hsv_lower, 'hsv_lower')
        upper = _check_hsv(self.hsv_upper, 'hsv_upper')
        if any(lo > hi for lo, hi in zip(lower, upper, strict=True)):
            raise ValueError(f'expected hsv_lower <= hsv_upper, got {lower} and {upper}')
        object.__setattr__(self, 'hsv_lower', lower)
        object.__setattr__(self, 'hsv_upper', upper)
        if not (math.isfinite(self.min_radius_px) and self.min_radius_px >= 2.0):
            raise ValueError(f'expected min_radius_px >= 2 [px], got {self.min_radius_px}')
        if not (math.isfinite(self.max_radius_px) and self.max_radius_px > self.min_radius_px):
            raise ValueError(
                f'expected max_radius_px > min_radius_px = {self.min_radius_px} [px], got '
                f'{self.max_radius_px}')
        for name in ('min_circularity', 'min_fill', 'min_confidence'):
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise ValueError(f'expected {name} in [0, 1], got {value}')
        if not (math.isfinite(self.min_chroma) and self.min_chroma >= 0.0):
            raise ValueError(f'expected min_chroma >= 0 [grey levels], got {self.min_chroma}')
        if not (math.isfinite(self.max_aspect_ratio) and self.max_aspect_ratio >= 1.0):
            raise ValueError(f'expected max_aspect_ratio >= 1, got {self.max_aspect_ratio}')
        for name, low in (('opening_px', 0), ('max_candidates', 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f'expected {name} an integer >= {low}, got {value!r}')

    @property
    def decimation(self) -> int:
        """Pixel step of the candidate search (1-4): the smallest ball keeps >= 2 px of
        radius."""
        return int(min(4, max(1, self.min_radius_px // 2.0)))


@dataclass(frozen=True)
class BallDetection:
    """A ball found in an image.

    Attributes
    ----------
    center : ndarray, shape (2,)
        ``(u, v)`` centre of the fitted ellipse [px], OpenCV convention.
    radius : float
        ``sqrt(a b)`` of the ellipse's semi-axes [px].
    confidence : float
        Fraction of the outline's rays whose edge lies on the ellipse, in [0, 1].
    axes : ndarray, shape (2,)
        Semi-axes ``(a, b)``, ``a >= b`` [px].
    angle : float
        Direction of the major axis from ``+u`` towards ``+v`` [rad].
    edge_points : ndarray, shape (n, 2)
        The sub-pixel edge points on the ellipse (inliers) [px], input of 3D localization.
    colour_bgr : ndarray, shape (3,)
        The ball's colour measured on its unclipped, unhighlighted pixels [grey levels].
    blur_px : float
        Standard deviation of the blur of its edge [px] (about 0.55 for a sharp image:
        pixel area and interpolation).
    """

    center: npt.NDArray[np.float64]
    radius: float
    confidence: float
    axes: npt.NDArray[np.float64]
    angle: float
    edge_points: npt.NDArray[np.float64]
    colour_bgr: npt.NDArray[np.float64]
    blur_px: float


# -- refinement --------------------------------------------------------------------------------

_SATURATED = 250  # a channel at or above this is treated as clipped
_STEP = 0.5  # sample spacing along the rays [px]
_LEVEL_LENGTH = 4.0  # length of the windows the edge's inside and outside levels come from [px]


def _channels(ball_bgr) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(ball-blind weights, chroma weights): unit BGR vectors with ``blind . ball = 0``,
    ``blind . grey > 0`` and ``chroma . grey = 0``, ``chroma . ball > 0`` (3-vectors: plain
    floats are faster than numpy here)."""
    b, g, r = (float(c) for c in ball_bgr)
    norm = math.sqrt(b * b + g * g + r * r)
    b, g, r = b / norm, g / norm, r / norm
    grey = 1.0 / math.sqrt(3.0)
    along = grey * (b + g + r)  # grey . ball = ball . grey
    blind = (grey - along * b, grey - along * g, grey - along * r)
    chroma = (b - along * grey, g - along * grey, r - along * grey)
    nb = math.sqrt(sum(x * x for x in blind))
    nc = math.sqrt(sum(x * x for x in chroma))
    return (np.array(blind, dtype=np.float32) / nb, np.array(chroma, dtype=np.float32) / nc)


@functools.lru_cache(maxsize=64)
def _ray_directions(n: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(cos, sin) of ``n`` directions equally spaced from 0."""
    phi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.cos(phi), np.sin(phi)


def _median(values: npt.NDArray) -> float:
    """Median of a 1-D array (``np.partition``; ``np.median``'s wrappers cost more here)."""
    n = len(values)
    part = np.partition(values, [(n - 1) // 2, n // 2])
    return 0.5 * float(part[(n - 1) // 2] + part[n // 2])


def _ball_colour(patch: npt.NDArray[np.uint8],
                 blob: npt.NDArray[np.uint8]) -> npt.NDArray | None:
    """BGR colour of the ball: the median direction (shading does not change it) of the blob's
    pixels away from its edge (no background mixed in), unclipped and without the brightest
    quarter (highlights), scaled to their median length (at most 400 pixels are used). None
    for a blob of fewer than 3 pixels."""
    core = cv2.erode(blob, np.ones((3, 3), np.uint8))
    inside = core if cv2.countNonZero(core) >= 8 else blob
    pixels = patch[inside > 0]
    if len(pixels) < 3:
        return None
    pixels = pixels[::max(1, len(pixels) // 400)]
    unclipped = pixels[pixels.max(axis=1) < _SATURATED]
    pixels = (unclipped if len(unclipped) >= 4 else pixels).astype(np.float64)
    norms = np.sqrt((pixels * pixels).sum(axis=1))
    keep = max(1, (3 * len(norms)) // 4)
    order = np.argpartition(norms, keep - 1)[:keep]  # without the brightest quarter
    pixels, norms = pixels[order], np.maximum(norms[order], 1e-9)
    return np.median(pixels / norms[:, None], axis=0) * _median(norms)


def _crossing(z: npt.NDArray, start: npt.NDArray | float) -> npt.NDArray[np.float64]:
    """Per row of normalized profiles ``z`` (rising through 0.5) sampled at
    ``start + k _STEP``, where they cross 0.5: after the samples below 0.5, counted (noise
    moves that count up and down alike, where a first crossing would come early), by linear
    interpolation between the two samples around that index. NaN where all samples are on one
    side."""
    n, m = z.shape
    below = (z < 0.5).sum(axis=1)
    flat = np.arange(0, n * m, m) + np.minimum(np.maximum(below, 1), m - 1)
    z0, z1 = z.ravel()[flat - 1], z.ravel()[flat]
    with np.errstate(invalid='ignore', divide='ignore'):
        # within the two samples (noise can make them both fall on one side of 0.5)
        position = below - 1 + np.minimum(np.maximum((0.5 - z0) / (z1 - z0), 0.0), 1.0)
    return np.where((below > 0) & (below < m), start + _STEP * position, np.nan)


def _normalized(signal: npt.NDArray, lo, hi) -> npt.NDArray:
    """``(signal - lo) / (hi - lo)`` per row (``lo`` a scalar or per row), NaN where
    ``hi <= lo``."""
    lo = np.reshape(lo, (-1, 1))
    span = np.reshape(hi, (-1, 1)) - lo
    with np.errstate(invalid='ignore', divide='ignore'):
        return (signal - lo) / np.where(span > 0.0, span, np.nan)


def _line_at(values: npt.NDArray, offset: int) -> npt.NDArray:
    """Per row, the least-squares line through ``values`` (sampled every ``_STEP``, the first
    ``offset`` samples from a point) evaluated at that point."""
    n = values.shape[1]
    j = np.arange(n) - 0.5 * (n - 1)
    return values.sum(axis=1) * (1.0 / n) - (values @ (j / (j @ j))) * (offset + 0.5 * (n - 1))


def _circular_mean(values: npt.NDArray, valid: npt.NDArray, k: int = 2) -> npt.NDArray:
    """Mean of each ray's value with those of its ``k`` neighbours on either side (the rays go
    round the ball); invalid rays count as the mean of the valid ones."""
    v = np.where(valid, values, values[valid].mean())
    return np.convolve(np.concatenate([v[-k:], v, v[:k]]), np.full(2 * k + 1, 1.0 / (2 * k + 1)),
                       'valid')


def _edges(signal: npt.NDArray[np.float32], t0: float, r0: float, half_width: float,
           inside_level: float | None, usable: npt.NDArray[np.int64] | int,
           sigma: float | None = None) -> tuple[npt.NDArray[np.float64], float]:
    """Sub-pixel edge on each ray and the edge's blur (standard deviation [px]).

    ``signal`` (n_rays, n_t) is sampled at ``t0 + k _STEP`` from the ray origin, rising from
    the ball (inside) to the background (outside); the first ``usable`` samples of each ray
    are in the image. A first pass takes half-way between the
    mean levels of the inner and outer parts of the search window ``|t - r0| <= half_width``,
    and the blur from the median 25 %-75 % width (1.349 sigma for a Gaussian blur) unless
    ``sigma`` is given (tracking: the blur measured a few frames ago). Then the
    outside level is extrapolated to that edge from a line through the samples just beyond the
    blurred edge (texture gradients), averaged over neighbouring rays, and so is the inside
    level unless it is known (``inside_level``: 0 in the ball-blind channel, however the ball
    is shaded), and the edge is found again between those levels. Finally it is moved out by
    ``sigma^2 / (2 rho)``, by which blur moves the half-way level of a convex outline of
    radius ``rho`` inwards (the median of a Rice distribution).
    """
    n_rays, n_t = signal.shape
    # sample index ranges of the search window and of its inner and outer halves
    lo_k = max(int(math.ceil((r0 - half_width - t0) / _STEP)), 0)
    hi_k = min(int(math.floor((r0 + half_width - t0) / _STEP)) + 1, n_t)
    quarter = max(1, (hi_k - lo_k) // 4)
    hi = signal[:, hi_k - quarter:hi_k].sum(axis=1) * (1.0 / quarter)
    lo = (inside_level if inside_level is not None
          else signal[:, lo_k:lo_k + quarter].sum(axis=1) * (1.0 / quarter))
    z = _normalized(signal[:, lo_k:hi_k], lo, hi)
    if sigma is None:
        found = _crossing(np.concatenate([z, z - 0.25, z + 0.25]), t0 + _STEP * lo_k)
        edge, q75, q25 = found[:n_rays], found[n_rays:2 * n_rays], found[2 * n_rays:]
        widths = (q75 - q25)[np.isfinite(q75) & np.isfinite(q25)]
        sigma = max(_median(widths) / 1.349, 0.3) if len(widths) else 0.7
    else:
        edge = _crossing(z, t0 + _STEP * lo_k)
    # local levels around the first edge
    length = int(round(_LEVEL_LENGTH / _STEP)) + 1
    gap = int(math.ceil(max(1.5, 2.5 * sigma) / _STEP))
    valid = np.isfinite(edge)
    k = np.rint((np.where(valid, edge, r0) - t0) / _STEP).astype(np.int64)
    valid &= (k >= gap) & (k < usable - gap - length)
    if not valid.any():
        return np.full(n_rays, np.nan), sigma
    k = np.where(valid, k, gap)
    e = t0 + _STEP * k
    flat = signal.ravel()
    at = (np.arange(0, n_rays * n_t, n_t) + k)[:, None]  # flat index of each ray's edge sample
    hi = _circular_mean(_line_at(flat[at + (gap + np.arange(length))], gap), valid)
    if inside_level is None:
        start = -min(gap + length - 1, int(k.min()))
        lo = _circular_mean(_line_at(flat[at + (start + np.arange(length))], start), valid)
    edge = _crossing(_normalized(flat[at + np.arange(-gap, gap + 1)], lo, hi), e - _STEP * gap)
    edge = np.where(valid, edge, np.nan)
    return edge + sigma * sigma / (2.0 * edge), sigma


def _ellipse_distance(fit, origin: npt.NDArray[np.float64],
                      directions: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Distance from ``origin`` along each unit direction to the ellipse ``fit`` (OpenCV's
    ``((cx, cy), (width, height), angle_deg)``)."""
    (cx, cy), (w, h), angle = fit
    a, b = 0.5 * w, 0.5 * h
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    # into the ellipse's axes, scaled to the unit circle
    o = origin - (cx, cy)
    ox, oy = (c * o[0] + s * o[1]) / a, (-s * o[0] + c * o[1]) / b
    dx = (c * directions[:, 0] + s * directions[:, 1]) / a
    dy = (-s * directions[:, 0] + c * directions[:, 1]) / b
    qa = dx * dx + dy * dy
    qb = ox * dx + oy * dy
    qc = ox * ox + oy * oy - 1.0
    return (-qb + np.sqrt(np.maximum(qb * qb - qa * qc, 0.0))) / qa


def _fit_outline(points: npt.NDArray[np.float64], origin: npt.NDArray[np.float64],
                 directions: npt.NDArray[np.float64], t: npt.NDArray[np.float64],
                 radius: float):
    """Robust ellipse fit through the edge points: (fit, inlier mask) or None.

    A fit through the edge points near the median distance, then one without the points
    farther (along their ray) from it than 3 robust standard deviations (the tolerance kept
    within [0.25, 0.5 + 0.03 r] px); the inliers are those within the tolerance of the second
    fit."""
    valid = np.isfinite(t)
    # a first cut around the median distance (the outline is no more elongated than 1.4:1)
    inliers = valid & (np.abs(t - _median(t[valid])) <= 0.2 * radius + 2.0) if valid.any() \
        else valid
    cap = 0.5 + 0.03 * radius
    fit = None
    for _ in range(2):
        if inliers.sum() < 8:
            return None
        fit = cv2.fitEllipseDirect(points[inliers].astype(np.float32))
        if not all(math.isfinite(x) for x in (*fit[0], *fit[1])) or min(fit[1]) <= 0.0:
            return None
        residual = np.full(len(t), np.inf)
        residual[valid] = t[valid] - _ellipse_distance(fit, origin, directions[valid])
        inner = residual[inliers]
        spread = _median(np.abs(inner - _median(inner)))
        tolerance = min(max(3.0 * 1.4826 * spread, 0.25), cap)
        fitted = inliers
        inliers = np.abs(residual) <= tolerance
        if np.array_equal(inliers, fitted):
            break  # no point to drop: the fit stands
    return fit, inliers


def _refine_blob(image: npt.NDArray[np.uint8], patch: npt.NDArray[np.uint8],
                 blob: npt.NDArray[np.uint8], offset: npt.NDArray[np.float64], moments,
                 params: DetectorParams,
                 prior: BallDetection | None = None) -> BallDetection | None:
    """Sub-pixel outline of one thresholded blob (`_refine_at` from its centroid and area).

    ``patch`` and ``blob`` are the blob's bounding box in the image and its mask, ``offset``
    the box's corner in the image, ``moments`` those of the blob's contour (box coordinates).
    A ``prior`` detection (the last frame's) lends its colour (a warm start).
    """
    center = offset + (moments['m10'] / moments['m00'], moments['m01'] / moments['m00'])
    r0 = math.sqrt(moments['m00'] / math.pi)
    ball_bgr = _ball_colour(patch, blob) if prior is None else prior.colour_bgr
    return _refine_at(image, center, r0, ball_bgr, params)


def _refine_at(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], r0: float,
               ball_bgr: npt.NDArray[np.float64] | None, params: DetectorParams,
               margin_px: float = 0.0, sigma: float | None = None) -> BallDetection | None:
    """Sub-pixel outline of a ball of colour ``ball_bgr`` near ``center`` with a radius near
    ``r0`` [px]: rays from ``center``, their edges (`_edges`, searched within
    ``0.15 r0 + 3 + margin_px`` of ``r0``), the robust ellipse fit (`_fit_outline`). None if
    the colour is unknown or too grey, or the inside of the outline is not of that colour."""
    if ball_bgr is None or np.linalg.norm(ball_bgr - ball_bgr.mean()) < max(params.min_chroma,
                                                                             1.0):
        return None
    blind, chroma = _channels(ball_bgr)
    n_rays = int(np.clip(round(2.0 * math.pi * r0), 32, 96))
    cos, sin = _ray_directions(n_rays)
    half_width = 0.15 * r0 + 3.0 + margin_px
    reach = half_width + 8.0  # room for the level windows beyond the search window
    t0 = max(0.3 * r0, r0 - reach)
    t = np.arange(t0, r0 + reach + _STEP, _STEP)
    map_x = (center[0] + np.outer(cos, t)).astype(np.float32)
    map_y = (center[1] + np.outer(sin, t)).astype(np.float32)
    h, w = image.shape[:2]
    # samples beyond the image (the ball near its border) must not be used: count, per ray,
    # those inside from the start (the image is convex and the rays start inside the ball)
    end = t[-1]
    if (end <= center[0] <= w - 1 - end) and (end <= center[1] <= h - 1 - end):
        in_image = len(t)
    else:
        in_image = np.count_nonzero((map_x >= 0.0) & (map_x <= w - 1) & (map_y >= 0.0)
                                    & (map_y <= h - 1), axis=1)
    samples = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
    # inside, the chroma of the ball's colour (a dark or grey round thing is no ball)
    strength = float(np.dot(ball_bgr, chroma))
    inner = max(1, int((r0 - half_width - t0) / _STEP))
    if not (samples[:, :inner] @ chroma).mean() > 0.5 * strength:
        return None
    # the ball-blind channel, unless the background is dark in it: then chroma
    signal = samples @ blind
    outer = (t > r0 + 0.5 * half_width) & (t <= r0 + half_width)
    inside_level = 0.0
    if not signal[:, outer].mean() > 0.25 * strength:
        signal = -(samples @ chroma)
        inside_level = None
    edge, sigma = _edges(signal, t0, r0, half_width, inside_level, in_image, sigma)
    directions = np.stack([cos, sin], axis=1)
    points = center + edge[:, None] * directions
    result = _fit_outline(points, center, directions, edge, r0)
    if result is None:
        return None
    fit, inliers = result
    (cx, cy), (fw, fh), angle = fit
    a, b = 0.5 * max(fw, fh), 0.5 * min(fw, fh)
    major = math.radians(angle) if fw >= fh else math.radians(angle) + 0.5 * math.pi
    major = (major + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    return BallDetection(center=np.array([cx, cy]), radius=math.sqrt(a * b),
                         confidence=float(inliers.mean()), axes=np.array([a, b]),
                         angle=major, edge_points=points[inliers], colour_bgr=ball_bgr,
                         blur_px=sigma)


def _accept(detection: BallDetection | None, params: DetectorParams) -> bool:
    return (detection is not None and detection.confidence >= params.min_confidence
            and detection.axes[0] <= params.max_aspect_ratio * detection.axes[1]
            and params.min_radius_px <= detection.radius <= params.max_radius_px)


def _elliptic(contour: npt.NDArray[np.int32], max_aspect_ratio: float) -> bool:
    """Whether a blob's pixel contour is close to an ellipse that is not too elongated: no
    point farther than ``1 + 0.12 r`` px from the ellipse fitted through them (squares,
    triangles and half discs are farther), an axis ratio within 1.15 times the limit."""
    if len(contour) < 6:
        return True  # a few pixels: left to the sub-pixel fit
    (cx, cy), (w, h), angle = cv2.fitEllipseDirect(contour)
    if not (math.isfinite(w) and math.isfinite(h)) or min(w, h) <= 0.0:
        return False
    a, b = 0.5 * w, 0.5 * h
    if max(a, b) > 1.15 * max_aspect_ratio * min(a, b) + 1.0:
        return False
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    d = contour[:, 0, :] - (cx, cy)
    rho = np.hypot((c * d[:, 0] + s * d[:, 1]) / a, (c * d[:, 1] - s * d[:, 0]) / b)
    radius = math.sqrt(a * b)
    return float(np.abs(rho - 1.0).max()) * radius <= 1.0 + 0.12 * radius


def _blobs(mask: npt.NDArray[np.uint8], scale: float, min_radius_px: float,
           params: DetectorParams) -> list[tuple[float, npt.NDArray[np.int32], dict]]:
    """Contours of the mask that may be the ball, best shape first: (score, contour, moments).

    ``scale`` is the mask's pixel size in image pixels; the area must fit the radius range
    (from ``min_radius_px``), the circularity and the fill (area not in holes) be high enough.
    """
    contours, hierarchy = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return []
    parents = hierarchy[0][:, 3]
    min_area = 0.5 * math.pi * (min_radius_px / scale) ** 2
    max_area = 1.5 * math.pi * (params.max_radius_px / scale) ** 2
    holes: dict[int, float] = {}
    for i in np.nonzero(parents >= 0)[0]:
        holes[parents[i]] = holes.get(parents[i], 0.0) + cv2.contourArea(contours[i])
    blobs = []
    for i in np.nonzero(parents < 0)[0]:
        contour = contours[i]
        moments = cv2.moments(contour)
        area = moments['m00']
        if not (min_area <= area <= max_area):
            continue
        # the contour of a digital disc runs through its outer pixels' centres: for blobs of a
        # few pixels compare the area with the enclosing circle's instead of the perimeter's
        perimeter = cv2.arcLength(contour, True)
        circularity = 4.0 * math.pi * area / perimeter ** 2 if perimeter > 0.0 else 0.0
        if area < 30.0:
            _, radius = cv2.minEnclosingCircle(contour)
            circularity = max(circularity, area / (math.pi * radius * radius))
        fill = 1.0 - holes.get(i, 0.0) / area
        if (circularity >= params.min_circularity and fill >= params.min_fill
                and _elliptic(contour, params.max_aspect_ratio)):
            blobs.append((circularity * fill, contour, moments))
    blobs.sort(key=lambda blob: -blob[0])
    return blobs


def _threshold(bgr: npt.NDArray[np.uint8], params: DetectorParams) -> npt.NDArray[np.uint8]:
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    return cv2.inRange(hsv, params.hsv_lower, params.hsv_upper)


def _check_image(bgr) -> npt.NDArray[np.uint8]:
    image = np.asarray(bgr)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(
            f'expected bgr_image a uint8 array of shape (height, width, 3), got {image.dtype} '
            f'{image.shape}')
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f'expected a non-empty bgr_image, got shape {image.shape}')
    return image


def refine_in_region(bgr_image: npt.ArrayLike, region: tuple[int, int, int, int],
                     params: DetectorParams = DetectorParams(),  # noqa: B008 (frozen)
                     near: npt.ArrayLike | None = None, prior: BallDetection | None = None,
                     max_blobs: int | None = None) -> BallDetection | None:
    """Detect the ball inside a region of the image, at full resolution.

    Parameters
    ----------
    bgr_image : ndarray, shape (height, width, 3), uint8
    region : tuple of 4 int
        ``(u0, v0, u1, v1)``: columns ``u0 <= u < u1``, rows ``v0 <= v < v1``, clipped to the
        image. The ball's blob must lie in it; its edge is sampled in the whole image.
    params : DetectorParams
    near : array-like, shape (2,), optional
        Expected centre [px]: blobs are tried in order of distance from it (default: best
        shape first).
    prior : BallDetection, optional
        The ball's last detection: its colour is used instead of measuring it (tracking).
    max_blobs : int, optional
        Number of blobs tried (default ``params.max_candidates``).

    Returns
    -------
    BallDetection or None
        The first accepted blob, in image pixel coordinates.
    """
    image = _check_image(bgr_image)
    h, w = image.shape[:2]
    u0, v0, u1, v1 = (int(x) for x in region)
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
    if u1 - u0 < 3 or v1 - v0 < 3:
        return None
    roi = image[v0:v1, u0:u1]
    mask = _threshold(roi, params)
    # at full resolution the threshold may keep a little less than the ball
    blobs = _blobs(mask, 1.0, 0.5 * params.min_radius_px, params)
    if near is not None:
        tx, ty = np.asarray(near, dtype=float) - (u0, v0)
        blobs.sort(key=lambda blob: math.hypot(blob[2]['m10'] / blob[2]['m00'] - tx,
                                               blob[2]['m01'] / blob[2]['m00'] - ty))
    for _, contour, _ in blobs[:params.max_candidates if max_blobs is None else max_blobs]:
        x, y, bw, bh = cv2.boundingRect(contour)
        # this blob alone (not its neighbours in the box), without its holes
        blob = np.zeros((bh, bw), np.uint8)
        cv2.drawContours(blob, [contour], -1, 255, cv2.FILLED, offset=(-x, -y))
        blob &= mask[y:y + bh, x:x + bw]
        moments = cv2.moments(contour - (x, y))
        detection = _refine_blob(image, roi[y:y + bh, x:x + bw], blob,
                                 np.array([u0 + x, v0 + y], dtype=float), moments, params,
                                 prior)
        if _accept(detection, params):
            return detection
    return None


def detect_ball(bgr_image: npt.ArrayLike,
                params: DetectorParams = DetectorParams()) -> BallDetection | None:  # noqa: B008
    """Find the yellow ball in a whole BGR image.

    Parameters
    ----------
    bgr_image : ndarray, shape (height, width, 3), uint8
        The image, in OpenCV's BGR channel order.
    params : DetectorParams
        Thresholds and shape limits (the defaults suit a yellow ball under indoor light).

    Returns
    -------
    BallDetection or None
        The accepted candidate of highest confidence, or None if there is no yellow ball.
    """
    image = _check_image(bgr_image)
    h, w = image.shape[:2]
    s = params.decimation if min(h, w) >= 8 * params.decimation else 1
    small = image if s == 1 else cv2.resize(image, (w // s, h // s),
                                            interpolation=cv2.INTER_AREA)
    mask = _threshold(small, params)
    if params.opening_px > 1:
        kernel = np.ones((params.opening_px, params.opening_px), np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    best = None
    for _, contour, moments in _blobs(mask, s, params.min_radius_px,
                                      params)[:params.max_candidates]:
        # the outline straight from the candidate (its centroid and area in the decimated
        # image), else from its blob thresholded again at full resolution
        x, y, bw, bh = cv2.boundingRect(contour)
        blob = np.zeros((bh, bw), np.uint8)
        cv2.drawContours(blob, [contour], -1, 255, cv2.FILLED, offset=(-x, -y))
        blob &= mask[y:y + bh, x:x + bw]
        # pixel i of the decimated image covers image pixels s i .. s i + s - 1
        center = s * np.array([moments['m10'], moments['m01']]) / moments['m00'] + 0.5 * (s - 1)
        patch = image[y * s:(y + bh) * s, x * s:(x + bw) * s]
        if s > 1:  # the colour from full-resolution pixels: fewer are mixed with others
            blob = cv2.resize(blob, (patch.shape[1], patch.shape[0]),
                              interpolation=cv2.INTER_NEAREST) & _threshold(patch, params)
        colour = _ball_colour(patch, blob)
        detection = _refine_at(image, center, s * math.sqrt(moments['m00'] / math.pi), colour,
                               params, margin_px=float(s))
        if not _accept(detection, params):
            margin = 0.25 * max(bw, bh) * s + 2 * s + 4
            region = (int(x * s - margin), int(y * s - margin), int((x + bw) * s + margin),
                      int((y + bh) * s + margin))
            detection = refine_in_region(image, region, params, near=center, max_blobs=1)
        if detection is not None and (best is None or detection.confidence > best.confidence):
            best = detection
    return best


class BallTracker:
    """Detects the ball frame after frame, searching near the last detection first.

    Parameters
    ----------
    params : DetectorParams
    search_radii : float
        Half-size of the tracking region in radii of the last detection, plus
        ``search_margin_px``.
    search_margin_px : float
        Extra half-size of the tracking region [px] (ball motion between frames).

    Attributes
    ----------
    last : BallDetection or None
        The last detection (None when lost).
    full_frame_searches : int
        Frames that needed a whole-image search.
    """

    def __init__(self, params: DetectorParams = DetectorParams(),  # noqa: B008 (frozen)
                 search_radii: float = 2.0, search_margin_px: float = 16.0) -> None:
        if not isinstance(params, DetectorParams):
            raise ValueError(f'expected params a DetectorParams, got {type(params).__name__}')
        if not (math.isfinite(search_radii) and search_radii >= 1.0):
            raise ValueError(f'expected search_radii >= 1, got {search_radii}')
        if not (math.isfinite(search_margin_px) and search_margin_px >= 0.0):
            raise ValueError(f'expected search_margin_px >= 0 [px], got {search_margin_px}')
        self.params = params
        self.search_radii = float(search_radii)
        self.search_margin_px = float(search_margin_px)
        self.last: BallDetection | None = None
        self.full_frame_searches = 0
        self._previous: npt.NDArray[np.float64] | None = None  # centre before the last
        self._frames = 0

    def reset(self) -> None:
        """Forget the last detection: the next frame is searched whole."""
        self.last = None
        self._previous = None

    def update(self, bgr_image: npt.ArrayLike) -> BallDetection | None:
        """Detect the ball in the next frame.

        With a last detection: first its outline is refined at the position predicted from
        the last two (half the last motion again), with its colour and blur (the blur is
        measured again every 16th frame); then the thresholded blobs of the tracking region are
        tried; last, the whole frame (`detect_ball`).
        """
        image = _check_image(bgr_image)
        detection = None
        last = self.last
        if last is not None:
            # half the last motion: smooth arm motion continues, a jittery one averages out
            velocity = (np.zeros(2) if self._previous is None
                        else 0.5 * (last.center - self._previous))
            self._frames += 1
            sigma = None if self._frames % 16 == 0 else last.blur_px
            detection = _refine_at(image, last.center + velocity, last.radius, last.colour_bgr,
                                   self.params, margin_px=1.0 + float(np.hypot(*velocity)),
                                   sigma=sigma)
            if not _accept(detection, self.params):
                half = self.search_radii * last.radius + self.search_margin_px
                u, v = last.center + velocity
                region = (int(math.floor(u - half)), int(math.floor(v - half)),
                          int(math.ceil(u + half)) + 1, int(math.ceil(v + half)) + 1)
                detection = refine_in_region(image, region, self.params, near=(u, v),
                                             prior=last)
        if detection is None:
            self.full_frame_searches += 1
            detection = detect_ball(image, self.params)
        self._previous = None if detection is None or last is None else last.center
        self.last = detection
        return detection
