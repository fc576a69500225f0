"""Kinematics and workspace of the pneumatic soft robot arm (SRA).

Implements sections 2-3 and 4.1 of ``001_b59ad71c956a1751`` (Xu et al. 2022, "Path planning and
intelligent control of a soft robot arm based on gas-structure coupling actuators"): the arm is
PEA1 (pneumatic extensible actuator) hanging from the mount, the PBA (pneumatic bendable actuator,
four bellows B1-B4) and PEA2. PEA1 and PEA2 share one pressure through a T-joint, so they extend
equally (``delta l1 = delta l2``).

Frame ``sra_mount`` (metres, right-handed):

- origin at the mount, i.e. the upper end of PEA1;
- ``+z`` along PEA1 pointing away from the mount (the arm hangs "straight down", so every
  reachable point has ``z > 0``: 0.574-0.990 m under positive pressure);
- ``+x`` along the bellows line from B4 to B2 (Fig 3B: "X-axis ... Lines B4 and B2");
- ``+y`` along the bellows line from B3 to B1 (Fig 3B: "Y-axis ... Lines B1 and B3"), so that
  ``x, y, z`` is right-handed.

Each inflated bellows lengthens its own side of the PBA and so pushes the end away from that
side: B4 (on the -x side) pushes towards +x, B2 towards -x, B3 (on the -y side) towards +y, B1
towards -y. With the usual counter-clockwise quadrant numbering this reproduces all four cases of
Fig 4 (Q1: B3+B4, Q2: B2+B3, Q3: B1+B2, Q4: B1+B4). The paper names the lines but not their
directions; of the two possible orientations of y only this one agrees with Fig 4 (with y running
from B1 to B3 the quadrants would be numbered clockwise).

Geometry (the reading of eq. (6)): the PBA is a point joint at ``(0, 0, l1)``, PEA2 is a straight
segment of the same length ``l1`` leaving the joint in the direction given by the bend direction
``phi`` (azimuth from +x towards +y) and the bend angle ``theta`` (from +z)::

    end = (l1 sin(theta) cos(phi), l1 sin(theta) sin(phi), l1 (1 + cos(theta)))

which satisfies ``(z_e - l1)^2 + x_e^2 + y_e^2 = l1^2`` exactly.
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from inflarm_model.validation import check_batch

CHAMBERS = ('PEA', 'B1', 'B2', 'B3', 'B4')
"""Pressure channels in command order; PEA is PEA1 and PEA2 joined by the T-pipe (one pressure)."""

CHAMBER_MAX_PRESSURE = 100e3
"""Highest gauge pressure a chamber is commanded to [Pa]: the simulated PEA reaches the top of the
positive-pressure work space (z = 0.99 m) at 100 kPa, and the bellows their full bend below it.
The default of the controller's output limit and of the simulator's accepted commands."""

BELLOWS_PUSH = {
    'B1': (0.0, -1.0),
    'B2': (-1.0, 0.0),
    'B3': (0.0, 1.0),
    'B4': (1.0, 0.0),
}
"""Unit direction in the x-y plane of ``sra_mount`` into which each inflated bellows bends the
end (away from its own side of the PBA)."""

QUADRANT_BELLOWS = {
    1: ('B4', 'B3'),
    2: ('B2', 'B3'),
    3: ('B2', 'B1'),
    4: ('B4', 'B1'),
}
"""Fig 4: quadrant -> (bellows driving x, bellows driving y). Quadrants are counter-clockwise:
Q1 ``x >= 0, y >= 0``, Q2 ``x < 0, y >= 0``, Q3 ``x < 0, y < 0``, Q4 ``x >= 0, y < 0``.
Note that the Q2 example of section 3.1 (B4 drives x, B1 drives y) disagrees with Fig 4
(Q2 = B2 + B3); B4 + B1 is Fig 4's Q4 pair."""


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned bounds of the SRA work space in ``sra_mount`` (section 2.2, Fig 5).

    Attributes
    ----------
    name : str
        What the bounds are for (used in error messages).
    x_max : float
        Largest ``|x|`` [m].
    y_max : float
        Largest ``|y|`` [m].
    z_min, z_max : float
        Range of ``z`` [m].
    """

    name: str
    x_max: float
    y_max: float
    z_min: float
    z_max: float


WORKSPACE_POSITIVE = Workspace('positive pressure', 0.202, 0.202, 0.574, 0.990)
"""Fig 5A: X, Y -202..202 mm, Z 574..990 mm."""

WORKSPACE_NEGATIVE = Workspace('positive and negative pressure', 0.350, 0.350, 0.162, 0.990)
"""Fig 5B: X, Y -350..350 mm, Z 162..990 mm."""


@dataclass(frozen=True)
class SoftArmConfiguration:
    """Configuration of the SRA in the point-joint geometry of eq. (6).

    Attributes
    ----------
    pea_length : float or ndarray, shape (...)
        Length ``l1`` of PEA1, equal to that of PEA2 [m].
    bend_direction : float or ndarray, shape (...)
        Azimuth ``phi`` of PEA2 about +z, from +x towards +y, in (-pi, pi] [rad]; 0 when straight.
    bend_angle : float or ndarray, shape (...)
        Angle ``theta`` between PEA2 and +z (PEA1), in [0, pi) [rad].
    """

    pea_length: float | npt.NDArray[np.float64]
    bend_direction: float | npt.NDArray[np.float64]
    bend_angle: float | npt.NDArray[np.float64]


def _scalar_or_array(a: npt.NDArray[np.float64]) -> float | npt.NDArray[np.float64]:
    return float(a) if a.ndim == 0 else a


def quadrant_of(x: npt.ArrayLike, y: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Quadrant (1-4) of the PBA's local frame in which ``(x, y)`` falls (section 3.1, step 2).

    Points on an axis go to the quadrant on the non-negative side (``x = 0`` counts as ``x >= 0``),
    so ``(0, 0)`` is in Q1.

    Parameters
    ----------
    x, y : array-like, broadcastable
        Target coordinates in ``sra_mount`` [m].

    Returns
    -------
    quadrant : ndarray of int, broadcast shape
        1, 2, 3 or 4 as in `QUADRANT_BELLOWS`.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError('expected finite x and y [m]')
    east = x >= 0.0
    north = y >= 0.0
    return np.where(north, np.where(east, 1, 2), np.where(east, 4, 3)).astype(np.int64)


def pea_length_from_end_point(end_point: npt.ArrayLike) -> float | npt.NDArray[np.float64]:
    """Length ``l1`` of PEA1 (= PEA2) that places the end at ``end_point``, eq. (6).

    ``(z_e - l1)^2 + x_e^2 + y_e^2 = l1^2`` is linear in ``l1``:
    ``l1 = (x_e^2 + y_e^2 + z_e^2) / (2 z_e)``.

    Parameters
    ----------
    end_point : array-like, shape (3,) or (..., 3)
        End point ``(x_e, y_e, z_e)`` in ``sra_mount`` [m]; ``z_e`` must be positive.

    Returns
    -------
    l1 : float or ndarray, shape (...)
        PEA length [m].
    """
    p = check_batch('end_point', end_point, 3, 'm', single=True)
    z = p[..., 2]
    if np.any(z <= 0.0):
        raise ValueError(
            f'expected end_point z > 0 m (the arm hangs along +z), got min z = {z.min():.3f} m')
    return _scalar_or_array(np.einsum('...i,...i->...', p, p) / (2.0 * z))


def forward_kinematics(
    pea_length: npt.ArrayLike, bend_direction: npt.ArrayLike, bend_angle: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """End point of the SRA from its configuration (point-joint geometry of eq. (6)).

    Parameters
    ----------
    pea_length : array-like, shape (...)
        ``l1``, length of each PEA [m], positive.
    bend_direction : array-like, shape (...)
        ``phi``, azimuth of the bend from +x towards +y [rad].
    bend_angle : array-like, shape (...)
        ``theta``, angle of PEA2 from +z, in [0, pi) [rad].

    Returns
    -------
    end_point : ndarray, shape (3,) or (..., 3)
        ``(l1 sin(theta) cos(phi), l1 sin(theta) sin(phi), l1 (1 + cos(theta)))`` in
        ``sra_mount`` [m].
    """
    l1 = np.asarray(pea_length, dtype=float)
    phi = np.asarray(bend_direction, dtype=float)
    theta = np.asarray(bend_angle, dtype=float)
    for name, a in (('pea_length', l1), ('bend_direction', phi), ('bend_angle', theta)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f'expected finite {name}, got {a}')
    if np.any(l1 <= 0.0):
        raise ValueError(f'expected pea_length > 0 m, got {l1}')
    if np.any(theta < 0.0) or np.any(theta >= np.pi):
        raise ValueError(f'expected bend_angle in [0, pi) rad, got {theta}')
    l1, phi, theta = np.broadcast_arrays(l1, phi, theta)
    s = l1 * np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), l1 * (1.0 + np.cos(theta))], axis=-1)


def inverse_kinematics(end_point: npt.ArrayLike) -> SoftArmConfiguration:
    """Configuration that places the SRA's end at ``end_point`` (inverse of `forward_kinematics`).

    With ``r = sqrt(x_e^2 + y_e^2)`` the isosceles geometry gives ``theta = 2 atan2(r, z_e)``,
    ``phi = atan2(y_e, x_e)`` and ``l1`` from eq. (6).

    Parameters
    ----------
    end_point : array-like, shape (3,) or (..., 3)
        End point in ``sra_mount`` [m], ``z_e > 0``.

    Returns
    -------
    SoftArmConfiguration
        Floats for one point, arrays of shape (...) for a batch.
    """
    p = check_batch('end_point', end_point, 3, 'm', single=True)
    l1 = np.asarray(pea_length_from_end_point(p))
    r = np.hypot(p[..., 0], p[..., 1])
    theta = 2.0 * np.arctan2(r, p[..., 2])
    phi = np.arctan2(p[..., 1], p[..., 0])
    return SoftArmConfiguration(
        _scalar_or_array(l1), _scalar_or_array(phi), _scalar_or_array(theta))


def central_axes(end_point: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Central-axis segments of PEA1 and PEA2 for a given end point (section 4.1, eqs. (5)-(6)).

    Parameters
    ----------
    end_point : array-like, shape (3,) or (..., 3)
        End point in ``sra_mount`` [m], ``z_e > 0``.

    Returns
    -------
    axes : ndarray, shape (2, 2, 3) or (..., 2, 2, 3)
        ``axes[..., 0, :, :]`` is PEA1 from the mount ``(0, 0, 0)`` to the PBA ``(0, 0, l1)``;
        ``axes[..., 1, :, :]`` is PEA2 from the PBA to the end point [m].
    """
    p = check_batch('end_point', end_point, 3, 'm', single=True)
    l1 = np.asarray(pea_length_from_end_point(p))
    joint = np.zeros(p.shape)
    joint[..., 2] = l1
    return np.stack([np.stack([np.zeros(p.shape), joint], axis=-2),
                     np.stack([joint, p], axis=-2)], axis=-3)


def check_chamber_pressures(
    pressures: dict[str, float], max_pressure: float = CHAMBER_MAX_PRESSURE
) -> dict[str, float]:
    """Validate set pressures by chamber name: known chambers, each within 0..``max_pressure``.

    Parameters
    ----------
    pressures : dict of str to float
        Some of `CHAMBERS` -> gauge pressure [Pa] (the valves give positive pressure only).
    max_pressure : float
        The chambers' rating [Pa].

    Returns
    -------
    dict of str to float
        The same pressures, as floats.

    Raises
    ------
    ValueError
        Naming the chamber and the problem, e.g. ``'PEA at 1e+300 Pa is outside 0..100000 Pa'``.
    """
    unknown = sorted(set(pressures) - set(CHAMBERS))
    if unknown:
        raise ValueError(f'unknown chambers {unknown}, expected some of {list(CHAMBERS)}')
    if not pressures:
        raise ValueError('no chamber named')
    checked = {}
    for name, value in pressures.items():
        pressure = float(value)
        if not 0.0 <= pressure <= max_pressure:  # NaN fails too
            raise ValueError(f'{name} at {pressure:.6g} Pa is outside 0..{max_pressure:.0f} Pa '
                             '(the valves give positive pressure only, up to the chamber '
                             'rating)')
        checked[name] = pressure
    return checked


def check_in_workspace(
    point: npt.ArrayLike, workspace: Workspace = WORKSPACE_POSITIVE, name: str = 'target'
) -> npt.NDArray[np.float64]:
    """Validate that points lie inside the work-space bounds (section 2.2; step 1 of 4.2).

    Parameters
    ----------
    point : array-like, shape (3,) or (..., 3)
        Points in ``sra_mount`` [m].
    workspace : Workspace
        `WORKSPACE_POSITIVE` (default) or `WORKSPACE_NEGATIVE`.
    name : str
        What the points are, for the error message.

    Returns
    -------
    point : ndarray, same shape
        The validated points as floats.

    Raises
    ------
    ValueError
        Naming the first violated bound, e.g.
        ``'target z = 1.100 m above the workspace maximum 0.990 m'``.
    """
    p = check_batch(name, point, 3, 'm', single=True)
    flat = p.reshape(-1, 3)
    checks = (
        (0, flat[:, 0] > workspace.x_max, 'above the workspace maximum', workspace.x_max),
        (0, flat[:, 0] < -workspace.x_max, 'below the workspace minimum', -workspace.x_max),
        (1, flat[:, 1] > workspace.y_max, 'above the workspace maximum', workspace.y_max),
        (1, flat[:, 1] < -workspace.y_max, 'below the workspace minimum', -workspace.y_max),
        (2, flat[:, 2] > workspace.z_max, 'above the workspace maximum', workspace.z_max),
        (2, flat[:, 2] < workspace.z_min, 'below the workspace minimum', workspace.z_min),
    )
    for axis, bad, relation, bound in checks:
        if np.any(bad):
            i = int(np.argmax(bad))
            index = ', '.join(str(int(j)) for j in np.unravel_index(i, p.shape[:-1]))
            label = name if p.ndim == 1 else f'{name}[{index}]'
            raise ValueError(
                f'{label} {"xyz"[axis]} = {flat[i, axis]:.3f} m {relation} {bound:.3f} m '
                f'({workspace.name} work space)')
    return p
