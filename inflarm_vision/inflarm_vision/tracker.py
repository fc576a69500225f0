"""Detection and tracking of a yellow ball in BGR images, with a sub-pixel outline.

The vision sensor of ``001_b59ad71c956a1751`` (3.1, 3.3, 4.3.2): an external camera records the
small yellow ball on the soft arm's end. numpy/OpenCV, the per-ray logic compiled (numba), no
rclpy.

Pipeline of `detect_ball` (one frame, whole image; `inflarm_vision/README.md` gives the why):

1. **Candidates** (`_candidates`) on a copy shrunk by ``s`` (`DetectorParams.decimation`):
   HSV thresholds, holes of each blob filled (highlights), rings and blobs outside the radius
   range dropped; a round blob gives its centroid and area radius, any other also the largest
   disc inside it (distance transform: a ball touching its colour, or partly hidden); ranked by
   shape times the square of the blob's mean saturation.
2. **Outline** (`_refine`: `_refine_at` twice). A coarse pass from the candidate, its edges on
   rays in the channel that best separates the ball's own samples from its surround (Fisher's
   discriminant, levels measured), then a fine pass with rays from that outline's centre in
   the best channel **blind to the ball's colour** (Fisher's discriminant in the plane of BGR
   orthogonal to it: the ball reads 0 however it is shaded). JPEG (4:2:0) halves the chroma's
   resolution and quantizes it coarsely, and the ball-blind channel is mostly chroma: where
   the fine pass finds less than 90 % of the outline, it is measured again in **luma** (full
   resolution; each ray's inside level measured, either polarity), the better kept; luma is
   also the last resort of the coarse pass, and the coarse channel that of the fine pass.
   While the fine outline's centre moves a quarter pixel or more from its start, it is
   measured again from there (twice at most: JPEG's chroma can put the rough centre a pixel
   off). On each ray the edge is where the signal crosses half-way between the inside and
   outside levels (`_edges`); a ray counts only if it is inside the ball just before its edge.
   The edge points are moved out by the blur's shift of a curved edge, ``sigma^2 / (2 r)``.
3. **Fit** (`_fit_outline`): a consensus circle through triples of edge points, least squares
   through its points without the far ones, an ellipse when 85 % of the outline is on it.
   ``confidence`` is the fraction of rays on the outline; a candidate is accepted (`_accept`) if
   it is high enough, the outline not too elongated, its radius in range, the rays off it
   one hidden arc at most, or two where 70 % of the outline is found (`_one_hidden_arc`; the
   fine pass's rays, from the coarse outline's centre, judge that: a coarse outline on
   ``min_confidence`` of its rays places the fine pass however its rays fall), and the ball's
   colour saturated (`DetectorParams.min_saturation`). The accepted candidate whose
   outline is on the most rays wins (a speck's whole outline is fewer rays than most of a
   ball's; the search stops at one on every ray of the most there are). Where none is
   accepted, each is refined again from 1.3 times its radius (a shaded ball's blob can be half
   its disc), believed on 80 % of the outline; where none is then, the large candidates of the
   colour mask with its threads cut (a ball joined by a thread to a wider thing of its colour);
   where none is then, those of the mask without its orange end (a ball merged with a thing of
   the orange hues, as coffee's foam), believed on 80 % as the retry's.
   The winner, where it is on less than 90 % of its rays, is **polished** (`_polish`, and so is
   the tracking pass's outline): measured once more in the ball-blind channel with the luma at
   the chroma's resolution (under JPEG the two resolutions bias that channel's half level) and
   moved there where that finds more of the outline.
4. **Small balls** (under 12 px): where their rays give no accepted outline (a blur of a third
   of the radius leaves too few samples for an edge's levels), the whole blurred disc is
   fitted to the ball-blind channel around the candidate (`_fit_disc`: a blurred ellipse on a
   sloping background, robust Levenberg-Marquardt), believed where 80 % of the rays from its
   centre agree with it.

`BallTracker` refines the fine outline at the position predicted from the last detections
with their colour and blur (tracking mode), then searches the candidates around it (`_search`,
the whole-frame search's code on a region), and falls back to `detect_ball` on the whole frame
when the ball is lost.

Pixel convention (OpenCV's): pixel ``i`` spans ``[i - 0.5, i + 0.5]``; ``center`` is the centre
of the fitted ellipse, ``radius`` ``sqrt(a b)`` of its semi-axes (the radius of the disc of equal
area). For the ball's 3D position use the edge points (`inflarm_vision.geometry.locate_ball`):
off the optical axis the ellipse's centre is not the image of the ball's centre.
"""

from dataclasses import dataclass, replace
import functools
import math

import cv2
import numba
import numpy as np
import numpy.typing as npt

__all__ = [
    'BallDetection',
    'BallTracker',
    'DetectorParams',
    'detect_ball',
    'refine_in_region',
    'warm_up',
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
        Range of apparent radii [px]. An outline found whole may measure up to 0.5 px under
        ``min_radius_px`` (a ball of a few pixels is measured that coarsely).
    min_circularity : float
        Smallest ``4 pi A / P^2`` of a blob whose centroid is a candidate (1 for a disc, pi / 4
        for a square; a pixel contour scores less than its shape). Any blob's largest inscribed
        disc is a candidate too.
    min_fill : float
        Smallest fraction of a blob's contour area that is not holes (rejects rings; a
        highlight punches a hole of a few percent).
    max_aspect_ratio : float
        Largest ratio of the fitted ellipse's axes. The image of a sphere at angle ``t`` off the
        optical axis has a ratio of about ``1 / cos(t)``: 1.15 at 30 deg, 1.31 at 40 deg.
    min_confidence : float
        Smallest fraction of the outline found on the fitted outline (a ball 30 % hidden scores
        about 0.65; a half disc, whose rays off the outline are one run of half of them, is
        refused whatever it scores).
    min_chroma : float
        Smallest distance of the ball's colour from grey [grey levels] (rejects dark, nearly
        grey blobs whose hue is noise).
    min_saturation : float
        Smallest saturation (1 - min / max of B, G, R) of the ball's colour as measured on its
        disc: a yellow ball's is high however it is shaded, dull orange wood and fur under
        JPEG are paler. The pixels' threshold (``hsv_lower``'s S, 130 = 0.51) is lower, so that
        JPEG's blurred chroma at the ball's edge stays in the mask.
    opening_px : int
        Size of the square structuring element of the opening on the decimated mask (0: none).
    max_candidates : int
        Number of candidates refined per frame, best first; where none of them is a ball, a
        whole-frame search also refines the best of those beyond them with a radius of
        ``2 min_radius_px`` or more (specks of the ball's colour, as on gravel, can outnumber
        and outscore a ball).
    """

    hsv_lower: tuple[int, int, int] = (17, 130, 45)
    hsv_upper: tuple[int, int, int] = (38, 255, 255)
    min_radius_px: float = 4.0
    max_radius_px: float = 150.0
    min_circularity: float = 0.6
    min_fill: float = 0.6
    max_aspect_ratio: float = 1.3
    min_confidence: float = 0.6
    min_chroma: float = 20.0
    min_saturation: float = 0.63
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
        for name in ('min_circularity', 'min_fill', 'min_confidence', 'min_saturation'):
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
# rays round an outline: one per pixel of it, within these (the whole-frame search compares
# outlines by their rays: a small ball's disc fit has as many as its ray pass)
_MIN_RAYS, _MAX_RAYS = 32, 96
_ACCEPT_SEPARATION = 1.6  # smallest separation of the ball from its surround (below: no ball)
_MIN_SEPARATION = 2.0  # of the ball-blind channel, below which the best of all is tried
_INSIDE_TOLERANCE = 0.35  # share of the edge's contrast a ray's inside level may be off
_SAME_COLOUR = 0.97  # cosine of the angle within which a colour is the ball's
# share of the disc within 0.7 of an outline that must be of the ball's colour (a ball 30 %
# hidden: 0.8 and more; a half disc, whose straight cut and arc fit a circle: about 0.55)
_MIN_OWN_SHARE = 0.65
_MIN_TOLERANCE_PX = 0.6  # smallest distance of an inlier from the fitted outline [px]
_MAX_HIDDEN_ARC = 0.36  # share of the outline another thing may hide (the spec: 30 %)
# the same below _COARSE_MIN_RADIUS_PX: on a few pixels of outline a small cap of a larger
# yellow shape (a corner, the end of a half disc) passes for a ball hidden by 30 %
_MAX_HIDDEN_ARC_SMALL = 0.28
_TWO_RUNS_MIN_SHARE = 0.7  # smallest share of the rays on an outline hidden in two arcs
_COARSE_MIN_RADIUS_PX = 8.0  # smaller guesses: too few samples for the levels of the coarse pass
_RIDGE = 4.0  # grey levels^2 added to the colour scatter of Fisher's discriminant
_LUMA = np.array([0.114, 0.587, 0.299], np.float32)  # ITU-R BT.601 (JPEG's), BGR order
_MIN_LUMA_CONTRAST = 10.0  # smallest step of luma across an edge of the luma pass [grey levels]
_CONFIDENT = 0.9  # confidence of a fine pass below which the luma pass measures it again
# how far under min_radius_px the fitted radius of an outline found whole (`_CONFIDENT`) may
# be [px]: a ball of a few pixels, in JPEG, measures that much smaller or larger than it is
_RADIUS_TOLERANCE_PX = 0.5
_THREAD_CUT = np.ones((3, 3), np.uint8)  # opening of the colour mask that cuts its threads
_NEW_CANDIDATE = 0.5  # distance from the candidates tried, over its radius, of a new one
_RETRY_SCALE = 1.3  # radius of a refused candidate's second refinement, over its blob's
_RETRY_MIN_CONFIDENCE = 0.8  # share of the outline that second refinement must find ...
_RETRY_MIN_ARC_PX = 100.0  # ... or this much of it (80 % of a 20 px ball's), if >= min_confidence
_TINY_MIN_SEPARATION = 5.0  # smallest separation from its surround of a ball from a tiny blob
_JIT = dict(cache=True, nogil=True, error_model='numpy')  # the compiled kernels, cached
# a small ball's whole blurred disc (`_fit_disc`), where its rays fail
_DISC_MIN_CONTRAST = 12.0  # smallest step of the ball-blind channel at its edge [grey levels]
# largest blur over radius: a blur near the radius rounds any blob; the spec's defocus (2.5 px)
# of its smallest ball (4 px) is 0.63, and the fitted radius of so small a ball is larger
_DISC_MAX_BLUR = 0.6
_DISC_PROFILE_TOLERANCE = 0.35  # largest RMS misfit of a ray's profile, over the edge's step
_DISC_ORANGE_PROFILE_TOLERANCE = 0.2  # the same for a disc in the colour mask's orange end:
_ORANGE_HUES = 4  # its lowest hues (17-20 by default; a yellow ball's are 21-30)
_DISC_EDGE_TOLERANCE_PX = 1.0  # largest distance of a ray's half-level from the model's [px]
_DISC_MIN_CONFIDENCE = 0.8  # share of the rays that must agree with the fitted disc
_DISC_MAX_RADIUS_PX = 12.0  # largest candidate whose disc is fitted where its rays fail [px]
_MOVED_PX = 0.25  # a fine outline this far from its start is measured again from it [px]
_FINE_REPEATS = 2  # at most this many times
_LEVEL_LENGTH = 4.0  # length of the windows the edge's inside and outside levels come from [px]
_LEVEL_SAMPLES = int(round(_LEVEL_LENGTH / _STEP)) + 1  # samples of such a window
_POLISH_MAX_MOVE_PX = 1.5  # a polished outline farther from the accepted one is another one [px]


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


@numba.njit(**_JIT)
def _crossing(z: npt.NDArray, level: float, start: float) -> float:
    """Where a profile ``z`` rising through ``level``, sampled at ``start + k _STEP``, crosses
    it: after the samples below it, counted (noise moves that count up and down alike, where a
    first crossing would come early), by linear interpolation between the two samples around
    that index. NaN where all samples are on one side."""
    below = 0
    for value in z:
        if value < level:
            below += 1
    if below == 0 or below == len(z):
        return np.nan
    z0, z1 = z[below - 1], z[below]
    share = (level - z0) / (z1 - z0)
    # within the two samples (noise can make them both fall on one side of the level)
    if share < 0.0:
        share = 0.0
    elif share > 1.0:
        share = 1.0
    return start + _STEP * (below - 1 + share)


@numba.njit(**_JIT)
def _line_at(values: npt.NDArray, weights: npt.NDArray, offset: float) -> float:
    """The least-squares line through ``values`` (sampled every ``_STEP``, the first
    ``offset`` samples from a point) evaluated at that point; ``weights`` (0 or 1 per sample)
    leave samples out. Fewer than 3 samples give their mean."""
    count = weights.sum()
    j = np.arange(len(values)) * 1.0
    per_sample = 1.0 / max(count, 1.0)  # no samples give 0 (unused)
    mean_j = (weights * j).sum() * per_sample
    mean_v = (weights * values).sum() * per_sample
    dj = j - mean_j
    sjj = (weights * dj * dj).sum()
    slope = (weights * dj * values).sum() / max(sjj, 1e-12) if count >= 3 else 0.0
    return mean_v + slope * (-offset - mean_j)


@numba.njit(**_JIT)
def _circular_mean(values: npt.NDArray, valid: npt.NDArray[np.bool_]) -> npt.NDArray:
    """Mean of each ray's value with those of its 2 neighbours on either side (the rays go
    round the ball); invalid rays count as the mean of the valid ones."""
    n = len(values)
    v = np.where(valid, values, values[valid].mean())
    out = np.empty(n)
    for i in range(n):
        out[i] = (v[(i - 2) % n] + v[(i - 1) % n] + v[i] + v[(i + 1) % n] + v[(i + 2) % n]) / 5.0
    return out


@numba.njit(**_JIT)
def _level_gap(sigma: float) -> int:
    """Samples between an edge of blur ``sigma`` [px] and the windows its levels come from
    (`_edges`): beyond the blur's reach, 2.5 ``sigma`` and 1.5 px at least."""
    return int(math.ceil(max(1.5, 2.5 * sigma) / _STEP))


@numba.njit(**_JIT)
def _samples_beyond_edge(sigma: float) -> int:
    """How many samples of a ray must be in the image beyond an edge of blur ``sigma`` for
    `_edges` to find it: the gap to the window of the outside level and a third of that window
    (the rest may be cut by the image's border: a ball near it)."""
    return _level_gap(sigma) + _LEVEL_SAMPLES // 3


@numba.njit(**_JIT)
def _edges(signal: npt.NDArray[np.float32], t0: float, r0: float, half_width: float,
           inside_level: float, usable: npt.NDArray[np.int64], sigma: float,
           min_contrast: float) -> tuple[npt.NDArray[np.float64], float]:
    """Sub-pixel edge on each ray and the edge's blur (standard deviation [px]).

    ``signal`` (n_rays, n_t) is sampled at ``t0 + k _STEP`` from the ray origin, rising from
    the ball (inside) to the background (outside); the first ``usable`` samples of each ray
    are in the image. A first pass takes half-way between the
    mean levels of the inner and outer parts of the search window ``|t - r0| <= half_width``,
    and the blur from the median 25 %-75 % width (1.349 sigma for a Gaussian blur) unless
    ``sigma`` is given (not NaN; tracking: the blur measured a few frames ago); with
    ``min_contrast`` (not NaN) the signal may fall as well as rise across the edge, by that
    much at least. Then the outside level is extrapolated to that edge from a line through the
    samples just beyond the blurred edge (texture gradients; those in the image, at least a
    third of the window: a ball near the border), averaged over neighbouring rays, and so is
    the inside level unless it is known (``inside_level`` not NaN: 0 in the ball-blind
    channel, however the ball is shaded), and the edge is found again between those levels.
    Finally it is moved out by ``sigma^2 / (2 rho)``, by which blur moves the half-way level
    of a convex outline of radius ``rho`` inwards (the median of a Rice distribution).
    """
    n_rays, n_t = signal.shape
    known_inside = not math.isnan(inside_level)
    either_polarity = not math.isnan(min_contrast)
    # sample index ranges of the search window and of its inner and outer quarters
    lo_k = max(int(math.ceil((r0 - half_width - t0) / _STEP)), 0)
    hi_k = min(int(math.floor((r0 + half_width - t0) / _STEP)) + 1, n_t)
    quarter = max(1, (hi_k - lo_k) // 4)
    start = t0 + _STEP * lo_k
    measure_blur = math.isnan(sigma)
    edge = np.full(n_rays, np.nan)
    widths = np.full(n_rays, np.nan)
    for i in range(n_rays):
        hi = signal[i, hi_k - quarter:hi_k].astype(np.float64).sum() / quarter
        lo = (inside_level if known_inside
              else signal[i, lo_k:lo_k + quarter].astype(np.float64).sum() / quarter)
        span = hi - lo
        if not (abs(span) >= min_contrast if either_polarity else span > 0.0):
            continue
        z = (signal[i, lo_k:hi_k] - lo) / span
        edge[i] = _crossing(z, 0.5, start)
        if measure_blur:
            widths[i] = _crossing(z, 0.75, start) - _crossing(z, 0.25, start)
    if measure_blur:
        measured = widths[np.isfinite(widths)]
        sigma = max(np.median(measured) / 1.349, 0.3) if len(measured) else 0.7
    # local levels around the first edge
    length, gap, beyond = _LEVEL_SAMPLES, _level_gap(sigma), _samples_beyond_edge(sigma)
    valid = np.zeros(n_rays, np.bool_)
    k = np.full(n_rays, gap)
    for i in range(n_rays):
        if math.isfinite(edge[i]):
            ki = int(np.rint((edge[i] - t0) / _STEP))
            if gap <= ki < usable[i] - beyond:
                valid[i], k[i] = True, ki
    if not valid.any():
        return np.full(n_rays, np.nan), sigma
    beyond_level = np.empty(n_rays)
    before_level = np.empty(n_rays)
    before_mean = np.empty(n_rays)
    values = np.empty(length)
    weights = np.empty(length)
    for i in range(n_rays):
        for j in range(length):
            at = k[i] + gap + j
            values[j] = signal[i, min(at, n_t - 1)]
            weights[j] = 1.0 if at < usable[i] else 0.0
        beyond_level[i] = _line_at(values, weights, gap)
        # the window before the edge ends a gap inside it, and starts at the ray's first sample
        # at the earliest
        for j in range(length):
            at = k[i] - (gap + length - 1) + j
            values[j] = signal[i, max(at, 0)]
            weights[j] = 1.0 if at >= 0 else 0.0
        before_level[i] = _line_at(values, weights, -(gap + length - 1))
        before_mean[i] = (values * weights).sum() / weights.sum()
    hi_levels = _circular_mean(beyond_level, valid)
    lo_levels = (np.full(n_rays, inside_level) if known_inside
                 else _circular_mean(before_level, valid))
    for i in range(n_rays):
        edge[i] = np.nan
        if not valid[i]:
            continue
        lo, span = lo_levels[i], hi_levels[i] - lo_levels[i]
        # a ray crosses the ball's edge only if it is still inside the ball before it: its own
        # level there near the inside level (not where background lies on both sides of a
        # texture edge: the cut of a half disc)
        if not ((before_mean[i] - lo) / span <= _INSIDE_TOLERANCE):
            continue
        if not (abs(span) >= min_contrast if either_polarity else span > 0.0):
            continue
        z = (signal[i, k[i] - gap:k[i] + gap + 1] - lo) / span
        found = _crossing(z, 0.5, t0 + _STEP * (k[i] - gap))
        edge[i] = found + sigma * sigma / (2.0 * found)
    return edge, sigma


@numba.njit(**_JIT)
def _mean_and_covariance(samples: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
    """Mean (k,) and covariance (k, k; ``np.cov``'s) of samples (n, k)."""
    n, k = samples.shape
    d = samples.astype(np.float64)
    mean = np.zeros(k)
    for j in range(k):
        mean[j] = d[:, j].sum() / n
        d[:, j] -= mean[j]
    covariance = np.zeros((k, k))
    for a in range(k):
        for b in range(a, k):
            covariance[a, b] = covariance[b, a] = (d[:, a] * d[:, b]).sum() / max(n - 1, 1)
    return mean, covariance


@numba.njit(**_JIT)
def _fisher(inside: npt.NDArray, outside: npt.NDArray) -> npt.NDArray[np.float64]:
    """Fisher's discriminant of two sets of samples (n, k): the unit weights ``w`` maximizing
    the separation of ``outside @ w`` above ``inside @ w``."""
    mean_in, scatter_in = _mean_and_covariance(inside)
    mean_out, scatter_out = _mean_and_covariance(outside)
    w = np.linalg.solve(scatter_in + scatter_out + _RIDGE * np.eye(len(mean_in)),
                        mean_out - mean_in)
    return w / max(math.sqrt((w * w).sum()), 1e-12)


@numba.njit(**_JIT)
def _separation(inside: npt.NDArray, outside: npt.NDArray, weights: npt.NDArray) -> float:
    """How well a channel separates two sets of BGR samples: the difference of their means
    over the root of the sum of their variances."""
    a = inside.astype(np.float64) @ weights.astype(np.float64)
    b = outside.astype(np.float64) @ weights.astype(np.float64)
    return (b.mean() - a.mean()) / math.sqrt(a.var() + b.var() + 1e-6)


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


@numba.njit(**_JIT)
def _circle_lsq(x: npt.NDArray[np.float64],
                y: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    """Least-squares circle through points ``(x, y)`` (Kasa, then three Gauss-Newton steps on
    the geometric distance): centre x, y, radius. The normal equations are formed about the
    points' mean, where they are well conditioned."""
    mx, my = x.mean(), y.mean()
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for i in range(len(x)):
        row = (x[i] - mx, y[i] - my, 1.0)
        rhs = row[0] * row[0] + row[1] * row[1]
        for j in range(3):
            b[j] += row[j] * rhs
            for k in range(3):
                a[j, k] += row[j] * row[k]
    sol = np.linalg.solve(a, b)
    cx, cy = 0.5 * sol[0], 0.5 * sol[1]
    r = math.sqrt(max(sol[2] + cx * cx + cy * cy, 1e-12))
    for _ in range(3):
        a[:] = 0.0
        b[:] = 0.0
        for i in range(len(x)):
            ox, oy = x[i] - mx - cx, y[i] - my - cy
            rho = math.hypot(ox, oy)
            row = (-ox / rho, -oy / rho, -1.0)
            for j in range(3):
                b[j] += row[j] * (r - rho)
                for k in range(3):
                    a[j, k] += row[j] * row[k]
        step = np.linalg.solve(a, b)
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
    return cx + mx, cy + my, r


@numba.njit(**_JIT)
def _fit_circle(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
                valid: npt.NDArray[np.bool_], cap: float):
    """The robust circle through the edge points ``(x, y)`` of the rays (``valid``: those
    with an edge): ``(ok, cx, cy, r, tolerance, residual, inliers)``.

    The consensus circle first: of the circles through triples of edge points a third of the
    way round from each other, the one most points lie within ``cap`` of (the first of
    those). Then twice: least squares through its inliers, the inliers again those within 3
    robust standard deviations of it (``tolerance``, kept within [`_MIN_TOLERANCE_PX`,
    ``cap``]). Not ``ok`` where fewer than 8 points support it."""
    n = len(x)
    residual = np.full(n, np.inf)
    inliers = np.zeros(n, np.bool_)
    best, best_cx, best_cy, best_r = -1, 0.0, 0.0, 0.0
    for i in range(n):
        j, k = (i + n // 3) % n, (i + (2 * n) // 3) % n
        if not (valid[i] and valid[j] and valid[k]):
            continue
        abx, aby, acx, acy = x[j] - x[i], y[j] - y[i], x[k] - x[i], y[k] - y[i]
        d = 2.0 * (abx * acy - aby * acx)
        nb, nc = abx * abx + aby * aby, acx * acx + acy * acy
        ux, uy = (acy * nb - aby * nc) / d, (abx * nc - acx * nb) / d
        cx, cy, r = x[i] + ux, y[i] + uy, math.hypot(ux, uy)
        if not math.isfinite(r):
            continue  # collinear
        support = 0
        for m in range(n):
            if valid[m] and abs(math.hypot(x[m] - cx, y[m] - cy) - r) <= cap:
                support += 1
        if support > best:
            best, best_cx, best_cy, best_r = support, cx, cy, r
    if best < 8:
        return False, 0.0, 0.0, 0.0, 0.0, residual, inliers
    for m in range(n):
        if valid[m]:
            residual[m] = math.hypot(x[m] - best_cx, y[m] - best_cy) - best_r
    inliers = np.abs(residual) <= cap
    cx, cy, r, tolerance = best_cx, best_cy, best_r, cap
    for _ in range(2):
        cx, cy, r = _circle_lsq(x[inliers], y[inliers])
        for m in range(n):
            if valid[m]:
                residual[m] = math.hypot(x[m] - cx, y[m] - cy) - r
        kept = residual[inliers]
        spread = np.median(np.abs(kept - np.median(kept)))
        tolerance = min(max(3.0 * 1.4826 * spread, _MIN_TOLERANCE_PX), cap)
        fitted, inliers = inliers, np.abs(residual) <= tolerance
        if inliers.sum() < 8:
            return False, 0.0, 0.0, 0.0, 0.0, residual, inliers
        if (inliers == fitted).all():
            break
    return True, cx, cy, r, tolerance, residual, inliers


def _fit_outline(points: npt.NDArray[np.float64], origin: npt.NDArray[np.float64],
                 directions: npt.NDArray[np.float64], t: npt.NDArray[np.float64],
                 radius: float):
    """Robust fit of the outline through the edge points: (fit, inlier mask) or None.

    The robust circle (`_fit_circle`; its points within ``0.5 + 0.03 radius`` px). An outline
    found on 85 % of the rays or more is then fitted by an ellipse (the image of a sphere off
    the optical axis), a partial one (occluded, or cut by texture) keeps the circle. ``fit``
    is OpenCV's ``((cx, cy), (width, height), angle_deg)``."""
    valid = np.isfinite(t)
    if valid.sum() < 8:
        return None
    ok, cx, cy, r, tolerance, residual, inliers = _fit_circle(
        np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1]), valid,
        0.5 + 0.03 * radius)
    if not ok:
        return None
    fit = ((cx, cy), (2.0 * r, 2.0 * r), 0.0)
    if inliers.mean() >= 0.85:
        ellipse = cv2.fitEllipseDirect(points[inliers].astype(np.float32))
        if all(math.isfinite(x) for x in (*ellipse[0], *ellipse[1])) and min(ellipse[1]) > 0.0:
            residual[valid] = t[valid] - _ellipse_distance(ellipse, origin, directions[valid])
            fit, inliers = ellipse, np.abs(residual) <= tolerance
    return fit, inliers


# -- a small ball: its whole blurred disc --------------------------------------------------------

@numba.njit(**_JIT)
def _blurred_disc(p: npt.NDArray[np.float64], dx: npt.NDArray[np.float64],
                  dy: npt.NDArray[np.float64],
                  jacobian: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The ball-blind channel of a blurred ball at pixel offsets ``(dx, dy)`` and, in
    ``jacobian`` (n, 9), its derivatives by the parameters ``p``: centre offset ``cx, cy``,
    radius ``rho``, blur ``s`` [px], background level ``b0 + b1 dx + b2 dy`` and ellipse
    ``e1, e2`` (the outline is ``|M (d - c)| = rho``, ``M = I + [[e1, e2], [e2, -e1]]``).

    The channel is 0 inside (however the ball is shaded) and the background outside, across
    the edge the normal CDF of the distance from it over ``s``; the edge moved in by
    ``s^2 / (2 rho)``, as blur moves a convex outline's half level (see `_edges`)."""
    cx, cy, rho, s, b0, b1, b2, e1, e2 = p
    out = np.empty(len(dx))
    for i in range(len(dx)):
        ux, uy = dx[i] - cx, dy[i] - cy
        w0, w1 = (1.0 + e1) * ux + e2 * uy, e2 * ux + (1.0 - e1) * uy
        r = max(math.hypot(w0, w1), 1e-9)
        u = (r - rho) / s + s / (2.0 * rho)
        cdf = 0.5 * math.erfc(-u / math.sqrt(2.0))
        level = b0 + b1 * dx[i] + b2 * dy[i]
        out[i] = level * cdf
        g = level * math.exp(-0.5 * u * u) / math.sqrt(2.0 * math.pi) / s  # d out / d r
        jacobian[i, 0] = -g * ((1.0 + e1) * w0 + e2 * w1) / r
        jacobian[i, 1] = -g * (e2 * w0 + (1.0 - e1) * w1) / r
        jacobian[i, 2] = -g * (1.0 + s * s / (2.0 * rho * rho))
        jacobian[i, 3] = g * (s / (2.0 * rho) - (r - rho) / s)
        jacobian[i, 4] = cdf
        jacobian[i, 5] = dx[i] * cdf
        jacobian[i, 6] = dy[i] * cdf
        jacobian[i, 7] = g * (w0 * ux - w1 * uy) / r
        jacobian[i, 8] = g * (w0 * uy + w1 * ux) / r
    return out


@numba.njit(**_JIT)
def _robust_cost(residual: npt.NDArray[np.float64], scale: float) -> float:
    """The soft-L1 cost (``2 (sqrt(1 + (r / scale)^2) - 1)``, summed): highlights and
    occluders are outliers."""
    z = residual / scale
    return (2.0 * (np.sqrt(1.0 + z * z) - 1.0)).sum()


@numba.njit(**_JIT)
def _fit_blurred_disc(signal: npt.NDArray[np.float64], dx: npt.NDArray[np.float64],
                      dy: npt.NDArray[np.float64], p0: npt.NDArray[np.float64],
                      lower: npt.NDArray[np.float64], upper: npt.NDArray[np.float64],
                      scale: float) -> npt.NDArray[np.float64]:
    """`_blurred_disc`'s parameters fitted to ``signal`` at ``(dx, dy)`` from ``p0``, within
    ``[lower, upper]``: Levenberg-Marquardt on the soft-L1 cost of residuals of ``scale``
    (iteratively reweighted), steps clipped to the bounds."""
    n = len(signal)
    p = p0.copy()
    jacobian = np.empty((n, 9))
    trial_jacobian = np.empty((n, 9))
    residual = _blurred_disc(p, dx, dy, jacobian) - signal
    cost = _robust_cost(residual, scale)
    damping = 1e-3
    for _ in range(30):
        weights = 1.0 / np.sqrt(1.0 + (residual / scale) ** 2)
        weighted = jacobian * weights[:, None]
        normal = weighted.T @ jacobian
        gradient = weighted.T @ residual
        improved = False
        for _ in range(8):
            damped = normal + damping * np.diag(np.diag(normal) + 1e-9)
            trial = np.minimum(np.maximum(p - np.linalg.solve(damped, gradient), lower), upper)
            trial_residual = _blurred_disc(trial, dx, dy, trial_jacobian) - signal
            trial_cost = _robust_cost(trial_residual, scale)
            if trial_cost < cost:
                improved = True
                break
            damping *= 10.0
        if not improved:
            break
        converged = cost - trial_cost <= 1e-4 * cost
        p, residual, cost = trial, trial_residual, trial_cost
        jacobian, trial_jacobian = trial_jacobian, jacobian
        damping = max(0.1 * damping, 1e-9)
        if converged:
            break
    return p


def _fit_disc(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], r0: float,
              ball_bgr: npt.NDArray[np.float64] | None,
              params: DetectorParams) -> BallDetection | None:
    """A small ball's outline from its whole disc: `_blurred_disc` fitted to the ball-blind
    channel of the pixels within ``1.5 r0 + 6`` px of ``center`` (`_fit_blurred_disc`).

    Under a blur of a third of its radius, a ball of a few pixels has too few samples along
    its rays for their edges' levels (`_edges`); its disc as a whole still has hundreds. A ray
    from the fitted centre agrees with the fit where its profile is within
    `_DISC_PROFILE_TOLERANCE` of the edge's step of the model's and its half level within
    `_DISC_EDGE_TOLERANCE_PX` of the model's (a corner of another shape is off both); a disc
    whose colour is in the colour mask's orange end (its `_ORANGE_HUES` lowest hues: specks
    of wood, fur and gravel under JPEG) must fit within `_DISC_ORANGE_PROFILE_TOLERANCE`; the
    fit is believed where `_DISC_MIN_CONFIDENCE` of them agree, the rays off it are as a
    hiding thing leaves them (`_one_hidden_arc`), the step is at least `_DISC_MIN_CONTRAST`
    and the blur at most `_DISC_MAX_BLUR` of the radius. None otherwise, or if the colour or
    the separation of the ball from its surround fails as in `_refine_at`."""
    if not _coloured(ball_bgr, params):
        return None
    h, w = image.shape[:2]
    half = int(math.ceil(1.5 * r0 + 6.0))
    cu, cv = int(round(center[0])), int(round(center[1]))
    u0, v0 = max(cu - half, 0), max(cv - half, 0)
    u1, v1 = min(cu + half + 1, w), min(cv + half + 1, h)
    pixels = image[v0:v1, u0:u1].reshape(-1, 3).astype(np.float32)
    vs, us = np.mgrid[v0:v1, u0:u1]
    dx = (us.ravel() - center[0]).astype(np.float64)
    dy = (vs.ravel() - center[1]).astype(np.float64)
    r = np.hypot(dx, dy)
    around = r >= r0 + 4.0
    outside = pixels[around]
    inside = _own_samples(pixels[r <= 0.7 * r0], ball_bgr)
    if inside is None or len(outside) < 16:
        return None
    weights, separation = _blind_channel(inside, outside, ball_bgr)
    if separation < _ACCEPT_SEPARATION:
        return None
    signal = (pixels @ weights).astype(np.float64)
    level = _median(signal[around])
    if level < _DISC_MIN_CONTRAST:
        return None
    reach = 0.5 * r0 + 2.0
    p = _fit_blurred_disc(
        signal, dx, dy, np.array([0.0, 0.0, r0, 1.0, level, 0.0, 0.0, 0.0, 0.0]),
        np.array([-reach, -reach, 0.5 * r0, 0.3, 0.0, -np.inf, -np.inf, -0.4, -0.4]),
        np.array([reach, reach, 1.8 * r0, max(r0, 1.0), np.inf, np.inf, np.inf, 0.4, 0.4]),
        0.1 * level)
    cx, cy, rho, s, b0, b1, b2, e1, e2 = (float(x) for x in p)
    if b0 < _DISC_MIN_CONTRAST or s > _DISC_MAX_BLUR * rho:
        return None
    # the rays from the fitted centre, across the fitted edge
    n_rays = _MIN_RAYS
    cos, sin = _ray_directions(n_rays)
    t = np.arange(max(rho - 2.0 * s - 1.0, 0.0), rho + 2.0 * s + 1.0 + 1e-9, _STEP)
    ray_dx = (cx + np.outer(cos, t)).ravel()
    ray_dy = (cy + np.outer(sin, t)).ravel()
    samples = cv2.remap(image, (center[0] + ray_dx).reshape(n_rays, -1).astype(np.float32),
                        (center[1] + ray_dy).reshape(n_rays, -1).astype(np.float32),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    profile = (samples.astype(np.float32) @ weights).astype(np.float64)
    model = _blurred_disc(p, ray_dx, ray_dy, np.empty((len(ray_dx), 9))).reshape(n_rays, -1)
    step = b0 + b1 * ray_dx.reshape(n_rays, -1)[:, -1] + b2 * ray_dy.reshape(n_rays, -1)[:, -1]
    misfit = np.sqrt(((profile - model) ** 2).mean(axis=1))
    tolerance = (_DISC_PROFILE_TOLERANCE if _hue(ball_bgr) >= params.hsv_lower[0] + _ORANGE_HUES
                 else _DISC_ORANGE_PROFILE_TOLERANCE)
    inliers = (step > 0.0) & (misfit <= tolerance * step)
    for i in np.nonzero(inliers)[0]:
        half_level = _crossing(profile[i] / step[i], 0.5, t[0])
        model_half_level = _crossing(model[i] / step[i], 0.5, t[0])
        inliers[i] = abs(half_level - model_half_level) <= _DISC_EDGE_TOLERANCE_PX
    if inliers.mean() < _DISC_MIN_CONFIDENCE or not _one_hidden_arc(inliers,
                                                                     _MAX_HIDDEN_ARC_SMALL):
        return None
    # M's eigenvalues are 1 +- e: semi-axes rho / (1 -+ e), the major one along the
    # eigenvector of 1 - e
    e = math.hypot(e1, e2)
    major = 0.5 * math.atan2(e2, e1) + 0.5 * math.pi
    major = (major + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    fitted = np.array([center[0] + cx, center[1] + cy])
    a, b = rho / (1.0 - e), rho / (1.0 + e)
    directions = np.stack([cos, sin], axis=1)[inliers]
    distance = _ellipse_distance(
        ((fitted[0], fitted[1]), (2.0 * a, 2.0 * b), math.degrees(major)), fitted, directions)
    return BallDetection(center=fitted, radius=math.sqrt(a * b),
                         confidence=float(inliers.mean()), axes=np.array([a, b]), angle=major,
                         edge_points=fitted + distance[:, None] * directions,
                         colour_bgr=ball_bgr, blur_px=s)


def _hue(bgr: npt.NDArray[np.float64]) -> int:
    """Hue of a BGR colour as the colour mask sees it (OpenCV's 8-bit scale, 0-180)."""
    pixel = np.clip(np.round(bgr), 0.0, 255.0).astype(np.uint8).reshape(1, 1, 3)
    return int(cv2.cvtColor(pixel, cv2.COLOR_BGR2HSV)[0, 0, 0])


def _coloured(ball_bgr: npt.NDArray[np.float64] | None, params: DetectorParams) -> bool:
    """Whether a measured ball colour is one (known, far enough from grey, saturated enough)."""
    return ball_bgr is not None and bool(
        np.linalg.norm(ball_bgr - ball_bgr.mean()) >= max(params.min_chroma, 1.0)
        and ball_bgr.min() <= (1.0 - params.min_saturation) * ball_bgr.max())


def _own_samples(inside: npt.NDArray[np.float32],
                 ball_bgr: npt.NDArray[np.float64]) -> npt.NDArray[np.float32] | None:
    """The BGR samples (n, 3) from within an outline that are of the ball's colour (not a
    highlight, not background where the ball is hidden or where the candidate is no ball);
    None unless the samples carry, on average, half the ball's chroma (a dark or grey round
    thing is no ball) and 8 of them are of its colour."""
    _, chroma = _channels(ball_bgr)
    if not (inside @ chroma).mean() > 0.5 * float(np.dot(ball_bgr, chroma)):
        return None
    own = _of_ball_colour(inside, ball_bgr)
    return inside[own] if own.sum() >= 8 else None


def _of_ball_colour(samples: npt.NDArray[np.float32],
                    ball_bgr: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Which BGR samples (n, 3) are of the ball's colour: within `_SAME_COLOUR` of its
    direction, however bright."""
    unit = (ball_bgr / np.linalg.norm(ball_bgr)).astype(np.float32)
    return samples @ unit > _SAME_COLOUR * np.sqrt(np.einsum('ij,ij->i', samples, samples))


def _blind_channel(inside: npt.NDArray[np.float32], outside: npt.NDArray[np.float32],
                   ball_bgr: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float32], float]:
    """Of the channels blind to the ball's colour (the plane orthogonal to it in BGR: 0 inside
    however the ball is shaded), the one that best separates the ball's own samples from
    those around it (Fisher's discriminant in that plane): its BGR weights and separation."""
    blind, _ = _channels(ball_bgr)
    unit = (ball_bgr / np.linalg.norm(ball_bgr)).astype(np.float32)
    # unit and blind are orthogonal unit vectors: their cross product is one too
    other = (unit[1] * blind[2] - unit[2] * blind[1], unit[2] * blind[0] - unit[0] * blind[2],
             unit[0] * blind[1] - unit[1] * blind[0])
    plane = np.array([blind, other])  # (2, 3)
    weights = (_fisher(inside @ plane.T, outside @ plane.T) @ plane).astype(np.float32)
    return weights, _separation(inside, outside, weights)


def _ring_samples(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], inner: float,
                  outer: float) -> npt.NDArray[np.float32]:
    """BGR samples (256, 3) of the ring from ``inner`` to ``outer`` px round ``center`` (0:
    a disc), spread evenly over its area."""
    rings = np.sqrt(inner * inner + (outer * outer - inner * inner)
                    * (np.arange(8) + 0.5) / 8.0)
    cos, sin = _ray_directions(32)
    map_x = (center[0] + np.outer(rings, cos)).astype(np.float32)
    map_y = (center[1] + np.outer(rings, sin)).astype(np.float32)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).reshape(-1, 3).astype(np.float32)


def _own_share(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], radius: float,
               ball_bgr: npt.NDArray[np.float64]) -> float:
    """Share of the disc within 0.7 ``radius`` of ``center`` that is of the ball's colour (a
    highlight is not of it)."""
    samples = _ring_samples(image, center, 0.0, 0.7 * radius)
    return float(np.mean(_of_ball_colour(samples, ball_bgr)))


def _surround_separation(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64],
                         radius: float, ball_bgr: npt.NDArray[np.float64] | None,
                         params: DetectorParams) -> float:
    """How clearly a ball's colour stands out from its surround: the separation
    (`_blind_channel`) of its own samples within 0.7 ``radius`` of ``center`` from those of the
    ring 2-6 px beyond that radius; 0 where the colour is none or the disc is not of it."""
    if not _coloured(ball_bgr, params):
        return 0.0
    inside = _own_samples(_ring_samples(image, center, 0.0, 0.7 * radius), ball_bgr)
    if inside is None:
        return 0.0
    return _blind_channel(inside, _ring_samples(image, center, radius + 2.0, radius + 6.0),
                          ball_bgr)[1]


def _refine_at(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], r0: float,
               ball_bgr: npt.NDArray[np.float64] | None, params: DetectorParams,
               margin_px: float = 0.0, sigma: float | None = None,
               channel: str = 'blind', placing: bool = False) -> BallDetection | None:
    """Sub-pixel outline of a ball of colour ``ball_bgr`` near ``center`` with a radius near
    ``r0`` [px]: rays from ``center``, their edges (`_edges`, searched within
    ``0.15 r0 + 3 + margin_px`` of ``r0``), the robust fit (`_fit_outline`). The edges are
    found in the ``channel``: ``'blind'``, the best ball-blind one (0 inside however the ball
    is shaded); ``'coarse'``, the one that best separates the ball from its surround whatever
    its shading (to place a rough guess); ``'luma'``, JPEG's luma (full resolution where JPEG
    halves the chroma's), with each ray's inside level measured and either polarity (a shaded
    ball is brighter than its surround on one side, darker on another). None if the colour is
    unknown or too grey, the inside of the outline is not of that colour (`_MIN_OWN_SHARE` of
    the fitted disc), nothing around the ball differs from it clearly, or the rays off the
    outline are not what a partly hidden ball leaves (`_one_hidden_arc`; the rays the image's
    border cuts short of the outline left out). An outline that only
    places the fine pass (``placing``) is kept without that last check where it is on
    ``min_confidence`` of its rays: the fine pass, with rays from its centre, makes it."""
    if not _coloured(ball_bgr, params):
        return None
    n_rays = int(np.clip(round(2.0 * math.pi * r0), _MIN_RAYS, _MAX_RAYS))
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
        in_image = np.full(n_rays, len(t))
    else:
        in_image = np.count_nonzero((map_x >= 0.0) & (map_x <= w - 1) & (map_y >= 0.0)
                                    & (map_y <= h - 1), axis=1)
    samples = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
    # the edge's signal: the ball-blind channel (`_blind_channel`); where nothing around
    # differs from the ball but in brightness (a dark surround), the best channel of all, with
    # the inside level measured
    n_t = len(t)
    inner = max(1, int((r0 - half_width - t0) / _STEP))
    outside_k = min(int((r0 + half_width - t0) / _STEP), n_t - 1)
    inside = _own_samples(samples[:, :inner].reshape(-1, 3).astype(np.float32), ball_bgr)
    if inside is None:
        return None
    outside = samples[:, outside_k:].reshape(-1, 3).astype(np.float32)
    if channel == 'luma':
        weights, inside_level = _LUMA, None
    else:
        weights, separation = _blind_channel(inside, outside, ball_bgr)
        inside_level = 0.0
        if channel == 'coarse' or separation < _MIN_SEPARATION:
            full = _fisher(inside, outside).astype(np.float32)
            if (full_separation := _separation(inside, outside, full)) > separation:
                weights, inside_level, separation = full, None, full_separation
        if separation < _ACCEPT_SEPARATION:
            return None  # nothing around it differs from it clearly: no edge
    signal = samples @ weights
    edge, sigma = _edges(signal, t0, r0, half_width,
                         math.nan if inside_level is None else inside_level,
                         in_image,
                         math.nan if sigma is None else sigma,
                         _MIN_LUMA_CONTRAST if channel == 'luma' else math.nan)
    directions = np.stack([cos, sin], axis=1)
    points = center + edge[:, None] * directions
    result = _fit_outline(points, center, directions, edge, r0)
    if result is None:
        return None
    fit, inliers = result
    # a ray the image's border cuts before its edge and what `_edges` needs beyond it found
    # no edge for want of samples: no evidence against the outline, so left out of the
    # judgement of its arcs (not of its confidence: half a disc cut by the border is no ball)
    judged = inliers
    if in_image.min() < len(t):
        needed = (_ellipse_distance(fit, center, directions)
                  + _STEP * _samples_beyond_edge(sigma))
        judged = inliers[np.isfinite(edge) | (t[np.maximum(in_image - 1, 0)] >= needed)]
    placed = placing and judged.mean() >= params.min_confidence
    max_hidden = _MAX_HIDDEN_ARC if r0 >= _COARSE_MIN_RADIUS_PX else _MAX_HIDDEN_ARC_SMALL
    if not placed and not _one_hidden_arc(judged, max_hidden):
        return None
    (cx, cy), (fw, fh), angle = fit
    a, b = 0.5 * max(fw, fh), 0.5 * min(fw, fh)
    if _own_share(image, np.array([cx, cy]), math.sqrt(a * b), ball_bgr) < _MIN_OWN_SHARE:
        return None
    major = math.radians(angle) if fw >= fh else math.radians(angle) + 0.5 * math.pi
    major = (major + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    return BallDetection(center=np.array([cx, cy]), radius=math.sqrt(a * b),
                         confidence=float(inliers.mean()), axes=np.array([a, b]), angle=major,
                         edge_points=points[inliers], colour_bgr=ball_bgr, blur_px=sigma)


def _one_hidden_arc(inliers: npt.NDArray[np.bool_], max_hidden: float) -> bool:
    """Whether the rays off the outline (round the ball, in order) are what a ball partly
    hidden by one thing leaves: long runs of them (over a tenth of the rays) of at most
    ``max_hidden`` of the rays in all, one of them, or two where `_TWO_RUNS_MIN_SHARE` of the
    rays are on the outline (the texture beside the hiding thing can take a second arc);
    short runs are texture and highlights. A bar of the ball's colour (two long runs, less of
    the outline found), or a half disc (one run of half the rays), is no ball."""
    n = len(inliers)
    if inliers.all():
        return True
    start = int(np.argmax(inliers))  # an inlier: no run is cut at the array's ends
    off = ~np.roll(inliers, -start)
    edges = np.diff(np.concatenate([[0], off.astype(np.int8), [0]]))
    runs = np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]
    long_runs = runs[runs > max(2, 0.1 * n)]
    return long_runs.sum() <= max_hidden * n and (
        len(long_runs) <= 1 or (len(long_runs) == 2 and inliers.mean() >= _TWO_RUNS_MIN_SHARE))


def _accept(detection: BallDetection | None, params: DetectorParams) -> bool:
    if detection is None:
        return False
    # a ball of about min_radius_px, found whole, may measure a little under it
    min_radius = params.min_radius_px - (_RADIUS_TOLERANCE_PX if detection.confidence
                                         >= _CONFIDENT else 0.0)
    return (detection.confidence >= params.min_confidence
            and detection.axes[0] <= params.max_aspect_ratio * detection.axes[1]
            and min_radius <= detection.radius <= params.max_radius_px)


def _disc_colour(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], radius: float,
                 params: DetectorParams) -> npt.NDArray | None:
    """`_ball_colour` of the thresholded pixels within ``0.75 radius`` of ``center``."""
    h, w = image.shape[:2]
    reach = max(1.0, 0.75 * radius)
    u0, v0 = max(int(center[0] - reach), 0), max(int(center[1] - reach), 0)
    u1, v1 = min(int(center[0] + reach) + 2, w), min(int(center[1] + reach) + 2, h)
    if u1 - u0 < 1 or v1 - v0 < 1:
        return None
    patch = image[v0:v1, u0:u1]
    disc = np.zeros(patch.shape[:2], np.uint8)
    cv2.circle(disc, (int(round((center[0] - u0) * 16)), int(round((center[1] - v0) * 16))),
               int(round(reach * 16)), 255, cv2.FILLED, cv2.LINE_8, shift=4)
    return _ball_colour(patch, disc & _threshold(patch, params))


def _refine(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], r0: float,
            params: DetectorParams, margin_px: float, colour: npt.NDArray | None = None,
            sigma: float | None = None) -> BallDetection | None:
    """The ball's outline from a rough centre and radius: `_refine_at` with a search window
    widened by ``margin_px`` (the uncertainty of the guess; in the coarse channel, else, if
    that fails for want of edges, the ball-blind one, then luma), then `_fine` from that
    outline's centre and radius with the narrow window, again from its own centre while that
    moves by `_MOVED_PX` or more; a candidate under `_DISC_MAX_RADIUS_PX` whose outline is not
    accepted, `_fit_disc`. ``colour`` is the ball's (measured on the disc when not given)."""
    if colour is None:
        colour = _disc_colour(image, center, r0, params)
    small = r0 < _COARSE_MIN_RADIUS_PX
    fine = None
    for channel in ('blind', 'luma') if small else ('coarse', 'blind', 'luma'):
        # the coarse pass only places the fine one, which judges the outline; a small
        # candidate's coarse outline is judged too (its rays are few, and specks of its size many)
        first = _refine_at(image, center, r0, colour, params, margin_px=margin_px, sigma=sigma,
                           channel=channel, placing=not small)
        if first is not None:
            # the outline measured again with rays from its own centre: from an off-centre
            # start the rays meet a part of the outline more often than its share of it
            start, fine = first.center, _fine(image, first.center, first.radius, colour, params,
                                              sigma=sigma)
            # and again from the fine outline's centre while that moves it (JPEG's chroma: the
            # rough centre can be a pixel off), if no worse
            for _ in range(_FINE_REPEATS):
                if fine is None or math.hypot(*(fine.center - start)) < _MOVED_PX:
                    break
                again = _fine(image, fine.center, fine.radius, colour, params, sigma=sigma)
                if again is None or again.confidence < fine.confidence or (
                        _accept(fine, params) and not _accept(again, params)):
                    break
                start, fine = fine.center, again
            break
    if r0 < _DISC_MAX_RADIUS_PX and not _accept(fine, params):
        disc = _fit_disc(image, center, r0, colour, params)
        if disc is not None and (fine is None or disc.confidence > fine.confidence):
            return disc
    return fine


def _luma_at_chroma_resolution(
        image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64],
        reach: float) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
    """The part of ``image`` within ``reach`` px of ``center`` with its luma (JPEG's YCrCb) at
    the resolution of 4:2:0 chroma: averaged over the 2 x 2 blocks JPEG's chroma is averaged
    over (from even pixels), then interpolated back (libjpeg's upsampling); and the part's
    top-left pixel ``(u, v)`` in the image."""
    h, w = image.shape[:2]
    u0 = max(int(center[0] - reach), 0) & ~1
    v0 = max(int(center[1] - reach), 0) & ~1
    u1, v1 = min(int(center[0] + reach) + 2, w), min(int(center[1] + reach) + 2, h)
    part = image[v0:v1, u0:u1]
    height, width = part.shape[:2]
    if height % 2 or width % 2:
        part = cv2.copyMakeBorder(part, 0, height % 2, 0, width % 2, cv2.BORDER_REPLICATE)
    ycrcb = cv2.cvtColor(part, cv2.COLOR_BGR2YCrCb)
    halved = cv2.resize(np.ascontiguousarray(ycrcb[:, :, 0]), (part.shape[1] // 2,
                        part.shape[0] // 2), interpolation=cv2.INTER_AREA)
    ycrcb[:, :, 0] = cv2.resize(halved, (part.shape[1], part.shape[0]),
                                interpolation=cv2.INTER_LINEAR)
    return (cv2.cvtColor(ycrcb, cv2.COLOR_YCrCb2BGR)[:height, :width],
            np.array([u0, v0], dtype=np.float64))


def _polish(image: npt.NDArray[np.uint8], detection: BallDetection,
            params: DetectorParams) -> BallDetection:
    """An accepted outline found on less than `_CONFIDENT` of its rays, measured once more in
    the ball-blind channel with the luma at the chroma's resolution
    (`_luma_at_chroma_resolution`): under JPEG's 4:2:0 that channel sums a sharp luma step and
    a chroma step twice as wide, whose half level can be a pixel off the edge; at one
    resolution it is one blurred step. The polished outline where it is accepted, on a larger
    share of its rays and within `_POLISH_MAX_MOVE_PX` of the first (with the first's blur,
    which tracking reuses on the image as it is); else ``detection``. It moves a ball, never
    finds one: in every pass, the blurred luma rounds small things of the ball's colour off
    into balls."""
    if detection.confidence >= _CONFIDENT:
        return detection  # most of the outline agrees already; the pass costs a fine one's time
    # the rays of `_refine_at` reach 1.15 r + 11 px from the centre; 2 px more for the filter
    part, corner = _luma_at_chroma_resolution(image, detection.center,
                                              1.15 * detection.radius + 13.0)
    polished = _refine_at(part, detection.center - corner, detection.radius,
                          detection.colour_bgr, params)
    if (not _accept(polished, params) or polished.confidence <= detection.confidence
            or math.hypot(*(polished.center + corner - detection.center))
            >= _POLISH_MAX_MOVE_PX):
        return detection
    return replace(polished, center=polished.center + corner,
                   edge_points=polished.edge_points + corner, blur_px=detection.blur_px)


def _fine(image: npt.NDArray[np.uint8], center: npt.NDArray[np.float64], r0: float,
          colour: npt.NDArray, params: DetectorParams, margin_px: float = 0.0,
          sigma: float | None = None) -> BallDetection | None:
    """The fine pass (`_refine_at` in the ball-blind channel), and again in luma when it finds
    less than `_CONFIDENT` of the outline (JPEG's chroma: half the resolution, coarser
    quantization), then in the coarse channel when neither reaches ``min_confidence`` (a
    surround that differs from the ball mostly in brightness, e.g. a dark sky on one side and a
    bright bar on the other): the one of higher confidence."""
    fine = None
    for channel, enough in (('blind', math.inf), ('luma', _CONFIDENT),
                            ('coarse', params.min_confidence)):
        if fine is not None and fine.confidence >= enough:
            continue
        found = _refine_at(image, center, r0, colour, params, margin_px=margin_px,
                           sigma=sigma, channel=channel)
        if found is not None and (fine is None or found.confidence > fine.confidence):
            fine = found
    return fine


def _candidates(mask: npt.NDArray[np.uint8], saturation: npt.NDArray[np.uint8], scale: float,
                min_radius_px: float, params: DetectorParams,
                limit: int | None = None) -> list[tuple[float, npt.NDArray[np.float64], float]]:
    """Where the ball may be in a colour mask of pixel size ``scale`` [image px]:
    ``(score, centre, radius)`` in mask pixels, best first. With ``limit``, the best ``limit``
    and then the best large one beyond them (a radius of ``2 min_radius_px`` or more), if any:
    the distance transforms of blobs that can be neither are not computed.

    Each blob's holes are filled (a highlight punches one). A round blob gives its centroid and
    the radius of its area; any blob also gives the largest disc inside it (the peak of its
    distance transform), which finds the ball when it touches something of its colour or is
    partly hidden. Blobs of an area outside the radius range, or mostly holes (rings), are
    no candidates. The score is the shape's (circularity, or the share of the blob the disc
    fills) times the square of the blob's mean saturation: a yellow ball's saturation does
    not change with its shading, while yellowish surroundings (wood, sand, skin) are paler."""
    contours, hierarchy = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    if hierarchy is None:
        return []
    parents = hierarchy[0][:, 3]
    min_area = 0.4 * math.pi * (min_radius_px / scale) ** 2
    max_area = 4.0 * math.pi * (params.max_radius_px / scale) ** 2
    holes: dict[int, float] = {}
    for i in np.nonzero(parents >= 0)[0]:
        holes[parents[i]] = holes.get(parents[i], 0.0) + cv2.contourArea(contours[i])
    found = []
    inscribed = []  # (vividness, blob, x, y, area) of the blobs whose largest disc is a guess
    for i in np.nonzero(parents < 0)[0]:
        contour = contours[i]
        moments = cv2.moments(contour)
        area = moments['m00']
        if area < min_area or 1.0 - holes.get(i, 0.0) / max(area, 1e-9) < params.min_fill:
            continue
        x, y, bw, bh = cv2.boundingRect(contour)
        blob = np.zeros((bh + 2, bw + 2), np.uint8)
        cv2.drawContours(blob, [contour], -1, 255, cv2.FILLED, offset=(1 - x, 1 - y))
        vivid = (cv2.mean(saturation[y:y + bh, x:x + bw], mask=blob[1:-1, 1:-1])[0] / 255.0) ** 2
        if area <= max_area:
            perimeter = cv2.arcLength(contour, True)
            circularity = 4.0 * math.pi * area / perimeter ** 2 if perimeter > 0.0 else 0.0
            if area < 30.0:
                _, radius = cv2.minEnclosingCircle(contour)
                circularity = max(circularity, area / (math.pi * radius * radius))
            if circularity >= params.min_circularity:
                centroid = np.array([moments['m10'], moments['m01']]) / area
                found.append((circularity * vivid, centroid, math.sqrt(area / math.pi)))
                if circularity >= 0.85:
                    continue  # a disc: its centroid is the better guess
        inscribed.append((vivid, blob, x, y, area))
    min_peak = 0.5 * min_radius_px / scale
    large = 2.0 * min_radius_px / scale
    inscribed.sort(key=lambda b: -b[0])
    for vivid, blob, x, y, area in inscribed:
        if limit is not None and len(found) >= limit:
            found.sort(key=lambda c: -c[0])
            most = 0.6 * vivid  # the most this blob's disc, or a later one's, scores
            # a large one's disc (peak + 0.5 >= large) holds pi (large - 1.5)^2 px at least
            if most <= found[limit - 1][0] and (
                    area < math.pi * (large - 1.5) ** 2
                    or any(c[2] >= large and c[0] >= most for c in found[limit:])):
                continue  # neither among the best nor the best large one beyond them
        distance = cv2.distanceTransform(blob, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        # The exact transform gives square roots of integers, their last bit following the
        # memory layout: on the integers, pixels tied at the peak stay tied, and the first wins.
        squared = np.rint(distance * distance)
        pv, pu = np.unravel_index(int(np.argmax(squared)), squared.shape)
        peak = math.sqrt(float(squared[pv, pu]))
        if min_peak <= peak <= params.max_radius_px / scale:
            found.append(((0.5 * min(1.0, math.pi * peak * peak / area) + 0.1) * vivid,
                          np.array([pu + x - 1.0, pv + y - 1.0]), peak + 0.5))
    found.sort(key=lambda c: -c[0])
    if limit is None:
        return found
    return found[:limit] + [c for c in found[limit:] if c[2] >= large][:1]


def _tiny_candidates(
        mask: npt.NDArray[np.uint8], saturation: npt.NDArray[np.uint8], scale: float,
        min_radius_px: float,
        limit: int | None = None) -> list[tuple[float, npt.NDArray[np.float64], float]]:
    """The blobs of a colour mask of pixel size ``scale`` [image px] that hold 0.4-1 times the
    pixels of the smallest ball's disc: ``(score, centre, radius)`` in mask pixels, best first
    (at most ``limit``). `_candidates` measures a blob by the area within its contour, which
    runs through its outer pixels' centres: on a blob of a few pixels, half of them. The score
    is the square of the blob's mean saturation, as there; the radius that of its pixels."""
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    pixels = stats[:, cv2.CC_STAT_AREA].astype(np.float64)
    disc = math.pi * (min_radius_px / scale) ** 2
    tiny = np.nonzero((pixels >= 0.4 * disc) & (pixels < disc))[0]
    tiny = tiny[tiny > 0]  # label 0: the background
    if len(tiny) == 0:
        return []
    vivid = (np.bincount(labels.ravel(), weights=saturation.ravel(), minlength=count)[tiny]
             / pixels[tiny] / 255.0) ** 2
    order = np.argsort(-vivid, kind='stable')[:limit]
    return [(float(vivid[k]), centroids[tiny[k]], math.sqrt(pixels[tiny[k]] / math.pi))
            for k in order]


def _retry_min_confidence(radius: float) -> float:
    """Share of its outline a refused candidate's second refinement must find: a half disc's
    rays from the larger radius cross its straight cut into the texture beyond, where a few
    edges can round off a short arc; a long arc of a circle is not found by chance, so a large
    ball needs only `_RETRY_MIN_ARC_PX` of outline (``min_confidence`` still applies)."""
    return min(_RETRY_MIN_CONFIDENCE, _RETRY_MIN_ARC_PX / (2.0 * math.pi * radius))


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


def _search(image: npt.NDArray[np.uint8], region: tuple[int, int, int, int],
            params: DetectorParams, near: npt.ArrayLike | None = None,
            prior: BallDetection | None = None) -> BallDetection | None:
    """The candidates of ``region`` (decimated as `DetectorParams.decimation` says) refined
    at full resolution: the accepted one whose outline is on the most rays (or, with
    ``near``, the first accepted in order of distance from it); where none is, the same from
    a larger radius, then with the colour mask's threads cut, then without its orange end,
    then of its tiny blobs; polished (`_polish`)."""
    h, w = image.shape[:2]
    u0, v0, u1, v1 = (int(x) for x in region)
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
    if u1 - u0 < 3 or v1 - v0 < 3:
        return None
    roi = image[v0:v1, u0:u1]
    s = params.decimation if min(roi.shape[:2]) >= 8 * params.decimation else 1
    small = roi if s == 1 else cv2.resize(roi, ((u1 - u0) // s, (v1 - v0) // s),
                                          interpolation=cv2.INTER_AREA)
    hsv = cv2.cvtColor(small, cv2.COLOR_BGR2HSV)

    def colour_mask(min_hue: int) -> npt.NDArray[np.uint8]:
        """The colour mask of the decimated region from hue ``min_hue`` up, opened."""
        mask = cv2.inRange(hsv, (min_hue,) + params.hsv_lower[1:], params.hsv_upper)
        if params.opening_px > 1 and params.min_radius_px / s >= params.opening_px:
            kernel = np.ones((params.opening_px, params.opening_px), np.uint8)
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        return mask

    mask = colour_mask(params.hsv_lower[0])

    # tracking tries the candidates by distance: all of them; a whole-frame search the best,
    # then the best large one (specks of the ball's colour, as on gravel, can outnumber a ball
    # whose blob merged with some of them, and outscore it)
    limit = None if near is not None else params.max_candidates

    def guesses_of(candidates: list) -> list:
        """``(centre, radius)`` in image px of the candidates of the decimated mask, in the
        order they are tried."""
        # pixel i of the decimated image covers image pixels s i .. s i + s - 1
        guesses = [(np.array([u0, v0]) + s * centre + 0.5 * (s - 1), s * radius)
                   for _, centre, radius in candidates]
        if near is not None:
            target = np.asarray(near, dtype=float)
            guesses.sort(key=lambda g: float(np.hypot(*(g[0] - target))))
            del guesses[params.max_candidates:]
        return guesses

    def new(guesses: list, tried: list) -> list:
        """The ``guesses`` not at a candidate ``tried`` already."""
        return [(centre, radius) for centre, radius in guesses
                if all(np.hypot(*(centre - at)) >= _NEW_CANDIDATE * radius for at, _ in tried)]

    def rounds():
        """``(guesses, radius scale, retry, tiny)`` of each round, the next where one finds
        none."""
        guesses = guesses_of(_candidates(mask, hsv[:, :, 1], s, params.min_radius_px, params,
                                         limit))
        yield guesses, 1.0, False, False
        # the blob may be smaller than the ball (its shaded limb falls below the colour
        # thresholds): each is refined again from a larger radius, whose rays can also cross
        # a half disc's straight cut into the texture beyond, so only most of an outline, or
        # a long arc of it, is believed there (`_retry_min_confidence`)
        yield guesses, _RETRY_SCALE, True, False
        # a ball joined by a thread to a wider thing of its colour is none of them (their
        # blob's largest disc is in the wider part): the large candidates of the mask with
        # its threads of 1-2 px cut, those that are new
        cut = new(guesses_of(_candidates(cv2.morphologyEx(mask, cv2.MORPH_OPEN, _THREAD_CUT),
                                         hsv[:, :, 1], s, 2.0 * params.min_radius_px, params,
                                         limit)), guesses)
        yield cut, 1.0, False, False
        # a ball beside a thing of the mask's orange end (coffee's foam, a cat's fur) merges
        # with it, and the blob's largest disc is in the thing: the large candidates of the
        # mask without its orange end (`_ORANGE_HUES`), those that are new, believed as the
        # retry's (specks of the yellow hues in fur and gravel are many, their outlines short)
        yellow = colour_mask(params.hsv_lower[0] + _ORANGE_HUES)
        yield new(guesses_of(_candidates(yellow, hsv[:, :, 1], s, 2.0 * params.min_radius_px,
                                         params, limit)), guesses + cut), 1.0, True, False
        # a blob of a few pixels (`_tiny_candidates`): the lit part of a small dark ball whose
        # shaded part is under the value threshold, a defocused ball's core; refined as the
        # first ones, and believed only where the ball's colour stands out clearly from its
        # surround (`_surround_separation`: specks of that size in wood, fur and gravel are
        # many)
        tiny_guesses = guesses_of(_tiny_candidates(mask, hsv[:, :, 1], s, params.min_radius_px,
                                                   limit))
        yield tiny_guesses, 1.0, False, True
        yield tiny_guesses, _RETRY_SCALE, True, True

    colour = None if prior is None else prior.colour_bgr
    for guesses, scale, retry, tiny in rounds():
        best = None
        for i, (centre, radius) in enumerate(guesses):
            if i == params.max_candidates and best is not None:
                break  # the large candidate beyond the best is tried where they all fail
            guess_colour = colour
            if tiny:
                # measured here once, for this check and the refinement
                if guess_colour is None:
                    guess_colour = _disc_colour(image, centre, scale * radius, params)
                if _surround_separation(image, centre, scale * radius, guess_colour,
                                        params) < 0.5 * _TINY_MIN_SEPARATION:
                    continue  # a ball's stands out by half as much at its rough guess already
            detection = _refine(image, centre, scale * radius, params,
                                scale * (0.25 * radius + s), guess_colour)
            if not _accept(detection, params) or (
                    retry and detection.confidence < _retry_min_confidence(detection.radius)) or (
                    tiny and _surround_separation(image, detection.center, detection.radius,
                                                  detection.colour_bgr, params)
                    < _TINY_MIN_SEPARATION):
                continue
            if near is not None:
                best = detection
                break  # tracking: the first accepted by distance
            # the most rays on the outline, not the largest share of them: a gravel speck's
            # whole outline (32 rays) must not outweigh nearly all of a large ball's (96)
            if best is None or len(detection.edge_points) > len(best.edge_points):
                best = detection
            if len(best.edge_points) >= _MAX_RAYS:
                break  # every ray of the most there are: no later candidate can have more
        if best is not None:
            return _polish(image, best, params)
    return None


def refine_in_region(bgr_image: npt.ArrayLike, region: tuple[int, int, int, int],
                     params: DetectorParams = DetectorParams(),  # noqa: B008 (frozen)
                     near: npt.ArrayLike | None = None,
                     prior: BallDetection | None = None) -> BallDetection | None:
    """Detect the ball inside a region of the image.

    Parameters
    ----------
    bgr_image : ndarray, shape (height, width, 3), uint8
    region : tuple of 4 int
        ``(u0, v0, u1, v1)``: columns ``u0 <= u < u1``, rows ``v0 <= v < v1``, clipped to the
        image. The ball's colour blob must lie in it; its edge is sampled in the whole image.
    params : DetectorParams
    near : array-like, shape (2,), optional
        Expected centre [px]: candidates are tried in order of distance from it, and the
        first accepted is returned (default: the accepted one whose outline is on the most
        rays).
    prior : BallDetection, optional
        The ball's last detection: its colour is used instead of measuring it (tracking).

    Returns
    -------
    BallDetection or None
        In image pixel coordinates.
    """
    return _search(_check_image(bgr_image), region, params, near, prior)


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
        The accepted candidate whose outline is on the most rays, or None if there is no
        yellow ball.
    """
    image = _check_image(bgr_image)
    return _search(image, (0, 0, image.shape[1], image.shape[0]), params)


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
    region_searches : int
        Frames whose predicted outline was not found, so the tracking region was searched.
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
        self.region_searches = 0
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
            # the predicted outline is the fine pass's guess already; the prediction is off by
            # up to 1.5 times the last motion when the ball moves as far as it did (3 |v| at a
            # reversal), and a start off the ball by more than its radius finds no outline
            margin = 1.0 + min(3.0 * float(np.hypot(*velocity)), last.radius)
            detection = _fine(image, last.center + velocity, last.radius, last.colour_bgr,
                              self.params, margin_px=margin, sigma=sigma)
            if _accept(detection, self.params):
                detection = _polish(image, detection, self.params)
            else:
                self.region_searches += 1
                half = self.search_radii * last.radius + self.search_margin_px
                u, v = last.center + velocity
                region = (int(math.floor(u - half)), int(math.floor(v - half)),
                          int(math.ceil(u + half)) + 1, int(math.ceil(v + half)) + 1)
                detection = _search(image, region, self.params, near=(u, v), prior=last)
        if detection is None:
            self.full_frame_searches += 1
            detection = detect_ball(image, self.params)
        self._previous = None if detection is None or last is None else last.center
        self.last = detection
        return detection


def warm_up() -> None:
    """Compile the detector's kernels, or load them from numba's on-disk cache.

    They compile on their first call (about 20 s on a 2-core machine, once per source change;
    later processes load them from the cache in ``__pycache__`` in about half a second). Call
    this where a first frame must not be slow: at set-up, or before a node subscribes."""
    image = np.full((120, 160, 3), 90, np.uint8)  # a yellow disc on grey
    cv2.circle(image, (80, 60), 20, (0, 200, 230), cv2.FILLED)
    if detect_ball(image) is None:
        raise RuntimeError('warm_up: the detector missed a plain yellow disc')
    # the small balls' disc fit runs only where their rays fail
    small = cv2.GaussianBlur(cv2.circle(np.full((40, 40, 3), 90, np.uint8), (20, 20), 5,
                                        (0, 200, 230), cv2.FILLED), (0, 0), 1.5)
    if _fit_disc(small, np.array([20.0, 20.0]), 5.0, np.array([0.0, 200.0, 230.0]),
                 DetectorParams()) is None:
        raise RuntimeError('warm_up: the disc fit missed a small blurred yellow disc')
    _samples_beyond_edge(1.0)  # `_refine_at` calls it only for a ball near the border
