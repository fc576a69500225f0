"""Robot description of the inflatable-link arm: DH tables and URDF text.

The rigid arm is Table 1 of 000_ce37cf035a0a87c6 (3 revolute motors, two links of length L).
The flexible arm is Table 2: each inflatable link becomes two rigid bodies of lengths l1 and
l2 = L - l1 joined by two orthogonal virtual torsional springs (pseudo-rigid-body model,
sections 2.1-2.2). Both are serial standard-DH chains,
T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), and are written here as URDF so that Pinocchio,
robot_state_publisher and RViz all read the same description.

URDF layout of a DH chain with joints 1..n:

- ``base_link`` is DH frame 0; joint i rotates about the z axis of frame i-1, so its origin
  in the parent link is the constant part Tz(d_{i-1}) Tx(a_{i-1}) Rx(alpha_{i-1}) of the
  previous row (identity for joint 1);
- the child link of joint i is named ``<joint>_link`` and carries a cylinder visual along the
  segment to the next frame origin;
- a fixed joint ``tip_joint`` places the ``tip`` link at DH frame n, the end effector.

The spring stiffness of eq. (2)/(7) is recorded per spring joint as a custom element in the
``INFLARM_XMLNS`` namespace, ``<inflarm:spring joint="spring_1" stiffness="172.71"/>``, a
direct child of ``<robot>``. URDF parsers (urdfdom, hence Pinocchio and robot_state_publisher)
skip elements they do not know; ``spring_stiffness_from_urdf`` reads it back.

Joint limits come from one table, ``JOINT_LIMITS``: the motor limits the simulated arm
(``inflarm_hw.inflatable_arm_sim``) clamps its targets to, and the spring range
``SPRING_DEFLECTION_LIMIT`` (|q_k| <= pi/2) outside which the elastostatic model
(``inflarm_model.elastostatics``) rejects a solution. The paper gives no limits: the motor ones
are our choice (see ``JOINT_LIMITS``).

Masses. Each body of an inflatable link carries an ``<inertial>`` for its share of the
PVC-coated fabric tube of section 3 (r = 55 mm, t = 0.5 mm, ``FABRIC_DENSITY``) and of the two
rigid end caps (``CAP_MASS`` each, at the link's ends), and a ``<collision>`` cylinder equal to
its visual. The paper gives neither the fabric density nor the cap mass; the values are
assumptions stated where they are defined. A default link weighs 0.295 kg.

The URDF of the default arm is checked in as ``urdf/inflarm_flexible.urdf`` and installed to
``share/inflarm_model/urdf/``; regenerate it with ``python -m inflarm_model.urdf
inflarm_model/urdf`` (a test keeps it equal to ``flexible_arm_urdf()``).
"""

import argparse
from collections.abc import Mapping, Sequence
import math
from pathlib import Path
import re
import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt

from inflarm_model.validation import check_positive

INFLARM_XMLNS = 'https://inflarm.org/xmlns/urdf'

BASE_LINK = 'base_link'
TIP_LINK = 'tip'
TIP_JOINT = 'tip_joint'

# Motors are DH joints 1, 2, 5 and virtual springs DH joints 3, 4, 6, 7 (Table 2, section 2.2).
MOTOR_JOINT_NAMES = ('joint_1', 'joint_2', 'joint_3')
SPRING_JOINT_NAMES = ('spring_1', 'spring_2', 'spring_3', 'spring_4')
RIGID_JOINT_NAMES = MOTOR_JOINT_NAMES
FLEXIBLE_JOINT_NAMES = (
    'joint_1', 'joint_2', 'spring_1', 'spring_2', 'joint_3', 'spring_3', 'spring_4',
)
# Positions of the motors and springs in q (DH order): the one definition every module uses.
MOTOR_INDICES = tuple(FLEXIBLE_JOINT_NAMES.index(name) for name in MOTOR_JOINT_NAMES)
SPRING_INDICES = tuple(FLEXIBLE_JOINT_NAMES.index(name) for name in SPRING_JOINT_NAMES)

DEFAULT_LINK_LENGTH = 0.6  # L [m], prototype of section 3
DEFAULT_SPRING_OFFSET = 0.03  # l1 [m], first wrinkle position, section 4
DEFAULT_RADIUS = 0.055  # r [m], prototype of section 3
DEFAULT_STIFFNESS = 172.71  # mean k [N m/rad] over Table 3, section 4
DEFAULT_WALL_THICKNESS = 0.5e-3  # t [m], prototype of section 3
# Assumptions (the paper gives neither): PVC-coated polyester fabric of 1300 kg/m^3 (PVC is
# 1300-1450, polyester 1380; 0.65 kg/m^2 at t = 0.5 mm), and each rigid cap a PVC disc of the
# link radius, 5 mm thick (66 g), with its steel band (10 x 0.5 mm, 14 g): 80 g.
FABRIC_DENSITY = 1300.0  # [kg/m^3]
CAP_MASS = 0.08  # [kg]

# Largest spring deflection of the pseudo-rigid-body model [rad]: beyond a quarter turn the two
# bodies of a link would fold onto each other, and nothing of eq. (2) holds.
SPRING_DEFLECTION_LIMIT = 0.5 * math.pi
# Position limits [rad] of every joint, by name: the one table the URDF, the simulated arm, the
# estimator and the IK check angles against. The paper gives none; ours keep the arm out of
# itself: the base turns a full turn, the shoulder lifts the first link up to 90 degrees either
# way, the elbow folds to 150 degrees, and the virtual springs stay within the +-90 degrees where
# the pseudo-rigid model means anything (SPRING_DEFLECTION_LIMIT, the estimator's model range).
JOINT_LIMITS = {
    'joint_1': (-math.pi, math.pi),
    'joint_2': (-0.5 * math.pi, 0.5 * math.pi),
    'joint_3': (-2.618, 2.618),
    **{name: (-SPRING_DEFLECTION_LIMIT, SPRING_DEFLECTION_LIMIT) for name in SPRING_JOINT_NAMES},
}
_WIDE_LIMIT = (-math.pi, math.pi)  # joints of other chains (the rigid arm of Table 1)
# Motor speed limit [rad/s]: the simulated motors' rate limit (ArmSimParams' default).
MOTOR_MAX_VELOCITY = 1.0
# Motor torque limit [N·m]: our choice, above the 180 N·m that 150 N at full reach (1.2 m)
# needs; the simulated motors are not torque-limited.
MOTOR_MAX_EFFORT = 200.0
# A spring is not driven: the speed and torque of its <limit> are placeholders (k pi/2 at
# k = 172.71 for the torque), as for joints of other chains.
_SPRING_VELOCITY, _SPRING_EFFORT = 10.0, 271.3
_FABRIC_RGBA = '0.93 0.93 0.88 1.0'  # PVC-coated fabric, off-white
_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_.-]*')


def _limit(name: str) -> str:
    """The URDF ``<limit>`` of joint ``name``: JOINT_LIMITS, and the motors' speed and torque."""
    lower, upper = JOINT_LIMITS.get(name, _WIDE_LIMIT)
    velocity, effort = ((MOTOR_MAX_VELOCITY, MOTOR_MAX_EFFORT) if name in MOTOR_JOINT_NAMES
                        else (_SPRING_VELOCITY, _SPRING_EFFORT))
    return (f'<limit lower="{_fmt(lower)}" upper="{_fmt(upper)}" effort="{_fmt(effort)}" '
            f'velocity="{_fmt(velocity)}"/>')


def check_joint_positions(names, positions) -> None:
    """Raise ValueError naming the first joint whose position is outside `JOINT_LIMITS`."""
    for name, position in zip(names, positions, strict=True):
        lower, upper = JOINT_LIMITS.get(name, _WIDE_LIMIT)
        if not lower <= position <= upper:
            raise ValueError(f'{name} at {position:.6g} rad is outside its limits '
                             f'[{lower:.4g}, {upper:.4g}] rad')


def rigid_dh_table(link_length: float = DEFAULT_LINK_LENGTH) -> npt.NDArray[np.float64]:
    """Constant DH parameters of the rigid 3-DOF arm, Table 1 of 000_ce37cf035a0a87c6.

    Parameters
    ----------
    link_length : float
        Link length L [m], positive and finite.

    Returns
    -------
    dh_table : ndarray, shape (3, 3)
        One row per joint, columns ``(a_i [m], alpha_i [rad], d_i [m])``; theta_i is the joint
        variable.

    Raises
    ------
    ValueError
        If ``link_length`` is not a positive finite number.
    """
    L = check_positive('link_length', link_length, 'm', 'length')
    return np.array([
        [0.0, math.pi / 2, 0.0],
        [L, 0.0, 0.0],
        [L, 0.0, 0.0],
    ])


def flexible_dh_table(
    link_length: float = DEFAULT_LINK_LENGTH, spring_offset: float = DEFAULT_SPRING_OFFSET
) -> npt.NDArray[np.float64]:
    """Constant DH parameters of the 7-DOF flexible arm, Table 2 of 000_ce37cf035a0a87c6.

    Parameters
    ----------
    link_length : float
        Inflatable link length L [m], positive and finite.
    spring_offset : float
        Distance l1 [m] of the virtual springs from the proximal joint of each link,
        ``0 < spring_offset < link_length``; the distal body has length l2 = L - l1.

    Returns
    -------
    dh_table : ndarray, shape (7, 3)
        One row per joint in DH order (motor, motor, spring, spring, motor, spring, spring),
        columns ``(a_i [m], alpha_i [rad], d_i [m])``.

    Raises
    ------
    ValueError
        If a length is not positive and finite or ``spring_offset >= link_length``.
    """
    L = check_positive('link_length', link_length, 'm', 'length')
    l1 = check_positive('spring_offset', spring_offset, 'm', 'length')
    if l1 >= L:
        raise ValueError(
            f'expected spring_offset < link_length ({L!r} m), got {spring_offset!r}'
        )
    l2 = L - l1
    h = math.pi / 2
    return np.array([
        [0.0, h, 0.0],
        [l1, -h, 0.0],
        [0.0, h, 0.0],
        [l2, 0.0, 0.0],
        [l1, -h, 0.0],
        [0.0, h, 0.0],
        [l2, 0.0, 0.0],
    ])


def check_dh_table(dh_table: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Validate a DH table and return it as a float array.

    Parameters
    ----------
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])``, n >= 1, all finite.

    Returns
    -------
    dh_table : ndarray, shape (n, 3)

    Raises
    ------
    ValueError
        If the shape is wrong or an entry is not finite.
    """
    try:
        table = np.array(dh_table, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f'expected dh_table as an array-like of shape (n, 3), got {dh_table!r}'
        ) from None
    if table.ndim != 2 or table.shape[1] != 3 or table.shape[0] < 1:
        raise ValueError(f'expected dh_table of shape (n, 3) with n >= 1, got {table.shape}')
    if not np.isfinite(table).all():
        raise ValueError('expected dh_table to be finite, got non-finite entries')
    return table


def check_joint_names(joint_names: Sequence[str], n: int) -> tuple[str, ...]:
    """Return ``joint_names`` as a tuple of n unique URDF joint names, or raise ValueError."""
    names = tuple(joint_names)
    if len(names) != n:
        raise ValueError(f'expected joint_names of length {n}, got {len(names)}')
    for name in names:
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise ValueError(
                f'expected joint_names to be identifiers like spring_1, got {name!r}'
            )
    link_names = {BASE_LINK, TIP_LINK, TIP_JOINT}
    link_names.update(f'{name}_link' for name in names)
    if len(set(names)) != n or link_names & set(names):
        raise ValueError(f'expected unique joint_names distinct from link names, got {names}')
    return names


def _fmt(x: float) -> str:
    # repr round-trips a float exactly, so Pinocchio sees the same numbers as numpy.
    return repr(float(x))


def _origin(xyz: Sequence[float], rpy: Sequence[float]) -> str:
    return (
        f'<origin xyz="{" ".join(_fmt(v) for v in xyz)}" '
        f'rpy="{" ".join(_fmt(v) for v in rpy)}"/>'
    )


def _segment_geometry(a: float, d: float, radius: float) -> tuple[str, str] | None:
    """Origin and cylinder of the DH segment from the link origin to (a, 0, d), link frame."""
    length = math.hypot(a, d)
    if length == 0.0:
        return None
    # URDF cylinders lie along z; pitching by atan2(a, d) turns z onto (a, 0, d) / length.
    return (_origin((a / 2, 0.0, d / 2), (0.0, math.atan2(a, d), 0.0)),
            f'<geometry><cylinder radius="{_fmt(radius)}" length="{_fmt(length)}"/></geometry>')


def segment_inertia(
    length: float, radius: float, thickness: float, caps: tuple[int, int]
) -> tuple[float, float, float, float]:
    """Mass properties of one body of an inflatable link: a tube and its end caps.

    The tube is a thin wall of ``FABRIC_DENSITY`` (mass 2 pi r t l rho); a cap is a thin disc of
    ``CAP_MASS`` and the tube's radius at one end of the body.

    Parameters
    ----------
    length : float
        Body length l [m] along its axis.
    radius : float
        Tube radius r [m].
    thickness : float
        Wall thickness t [m].
    caps : (int, int)
        Number of caps (0 or 1) at the proximal (s = 0) and distal (s = l) end.

    Returns
    -------
    mass : float
        [kg].
    center : float
        Centre of mass along the axis, from the proximal end [m].
    axial, transverse : float
        Moments of inertia about the axis and about a transverse axis through the centre of
        mass [kg m^2].
    """
    tube = 2.0 * math.pi * radius * thickness * length * FABRIC_DENSITY
    proximal, distal = CAP_MASS * caps[0], CAP_MASS * caps[1]
    mass = tube + proximal + distal
    center = (tube * length / 2 + distal * length) / mass
    axial = tube * radius**2 + (proximal + distal) * radius**2 / 2
    transverse = (tube * (radius**2 / 2 + length**2 / 12 + (length / 2 - center) ** 2)
                  + proximal * (radius**2 / 4 + center**2)
                  + distal * (radius**2 / 4 + (length - center) ** 2))
    return mass, center, axial, transverse


def _segment_elements(a: float, d: float, radius: float, thickness: float,
                      caps: tuple[int, int] | None) -> str:
    """Visual, collision and (with ``caps``) inertial of the segment to (a, 0, d)."""
    geometry = _segment_geometry(a, d, radius)
    if geometry is None:
        return ''
    origin, cylinder = geometry
    text = (
        f'    <visual>\n      {origin}\n      {cylinder}\n'
        '      <material name="fabric"/>\n    </visual>\n'
        f'    <collision>\n      {origin}\n      {cylinder}\n    </collision>\n'
    )
    if caps is None:
        return text
    length = math.hypot(a, d)
    mass, center, axial, transverse = segment_inertia(length, radius, thickness, caps)
    ux, uz = a / length, d / length
    return text + (
        '    <inertial>\n'
        f'      {_origin((center * ux, 0.0, center * uz), (0.0, math.atan2(a, d), 0.0))}\n'
        f'      <mass value="{_fmt(mass)}"/>\n'
        f'      <inertia ixx="{_fmt(transverse)}" ixy="0.0" ixz="0.0" iyy="{_fmt(transverse)}" '
        f'iyz="0.0" izz="{_fmt(axial)}"/>\n'
        '    </inertial>\n'
    )



def dh_chain_urdf(
    robot_name: str,
    dh_table: npt.ArrayLike,
    joint_names: Sequence[str],
    radius: float = DEFAULT_RADIUS,
    spring_stiffness: Mapping[str, float] | None = None,
    caps: Mapping[str, tuple[int, int]] | None = None,
    thickness: float = DEFAULT_WALL_THICKNESS,
) -> str:
    """URDF text of a serial revolute chain given by a standard DH table.

    Parameters
    ----------
    robot_name : str
        Value of ``<robot name=...>``.
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])`` with
        T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i).
    joint_names : sequence of str, length n
        Names of the revolute joints in DH order; limits from ``JOINT_LIMITS`` (a full turn
        for names not in it).
    radius : float
        Radius [m] of the cylinder visuals and collisions drawn along the links.
    spring_stiffness : mapping of str to float, optional
        Stiffness k [N m/rad] of eq. (2) per spring joint name, recorded as
        ``<inflarm:spring joint=... stiffness=.../>`` elements.
    caps : mapping of str to (int, int), optional
        Inflatable-link bodies: per joint name whose child link carries a segment, the caps
        (0 or 1) at its proximal and distal end. Those links get an ``<inertial>`` from
        ``segment_inertia``; without ``caps`` no link has one.
    thickness : float
        Tube wall thickness t [m] of the inertials.

    Returns
    -------
    str
        URDF document: root ``base_link`` (DH frame 0), joints in DH order, fixed ``tip`` link
        at DH frame n.

    Raises
    ------
    ValueError
        On a malformed table, names of the wrong length or duplicated, a non-positive radius
        or thickness, a stiffness that is not positive and finite or names an unknown joint,
        or caps for an unknown joint.
    """
    table = check_dh_table(dh_table)
    names = check_joint_names(joint_names, table.shape[0])
    radius = check_positive('radius', radius, 'm', 'length')
    thickness = check_positive('thickness', thickness, 'm', 'length')
    springs = {}
    for joint, k in (spring_stiffness or {}).items():
        if joint not in names:
            raise ValueError(f'expected spring_stiffness keys among {names}, got {joint!r}')
        springs[joint] = check_positive(f'spring_stiffness[{joint!r}]', k, 'N m/rad', 'stiffness')
    caps = dict(caps or {})
    if not set(caps) <= set(names):
        raise ValueError(f'expected caps keys among {names}, got {sorted(caps)}')

    parts = [
        '<?xml version="1.0"?>\n',
        f'<robot name={quoteattr(robot_name)} xmlns:inflarm="{INFLARM_XMLNS}">\n',
        '  <!-- Generated by inflarm_model.urdf from a standard DH table; limits from '
        'inflarm_model.urdf.JOINT_LIMITS, masses from its stated assumptions. -->\n',
    ]
    parts.append(f'  <material name="fabric"><color rgba="{_FABRIC_RGBA}"/></material>\n')
    parts += [
        f'  <inflarm:spring joint="{joint}" stiffness="{_fmt(k)}"/>\n'
        for joint, k in springs.items()
    ]
    parts.append(f'  <link name="{BASE_LINK}"/>\n')
    parent = BASE_LINK
    previous = (0.0, 0.0, 0.0)  # joint 1 sits at the origin of frame 0
    for name, (a, alpha, d) in zip(names, table, strict=True):
        prev_a, prev_alpha, prev_d = previous
        child = f'{name}_link'
        parts.append(
            f'  <joint name="{name}" type="revolute">\n'
            f'    <parent link="{parent}"/>\n'
            f'    <child link="{child}"/>\n'
            f'    {_origin((prev_a, 0.0, prev_d), (prev_alpha, 0.0, 0.0))}\n'
            '    <axis xyz="0 0 1"/>\n'
            f'    {_limit(name)}\n'
            '  </joint>\n'
        )
        body = _segment_elements(a, d, radius, thickness, caps.get(name))
        parts.append(
            f'  <link name="{child}">\n{body}  </link>\n' if body
            else f'  <link name="{child}"/>\n'
        )
        parent, previous = child, (a, alpha, d)
    prev_a, prev_alpha, prev_d = previous
    parts.append(
        f'  <joint name="{TIP_JOINT}" type="fixed">\n'
        f'    <parent link="{parent}"/>\n'
        f'    <child link="{TIP_LINK}"/>\n'
        f'    {_origin((prev_a, 0.0, prev_d), (prev_alpha, 0.0, 0.0))}\n'
        '  </joint>\n'
        f'  <link name="{TIP_LINK}"/>\n'
        '</robot>\n'
    )
    return ''.join(parts)


def rigid_arm_urdf(
    link_length: float = DEFAULT_LINK_LENGTH, radius: float = DEFAULT_RADIUS
) -> str:
    """URDF text of the rigid 3-DOF arm of Table 1 (joints ``joint_1`` .. ``joint_3``).

    Parameters
    ----------
    link_length : float
        Link length L [m].
    radius : float
        Link radius [m] for the cylinder visuals.

    Returns
    -------
    str
        URDF document, see ``dh_chain_urdf``.

    Raises
    ------
    ValueError
        If a length is not positive and finite.
    """
    # Each rigid link is a whole inflatable link: both caps on it.
    return dh_chain_urdf('inflarm_rigid', rigid_dh_table(link_length), RIGID_JOINT_NAMES, radius,
                         caps={'joint_2': (1, 1), 'joint_3': (1, 1)})


# Caps (proximal, distal) of the inflatable-link bodies of the flexible arm, by joint name.
FLEXIBLE_CAPS: Mapping[str, tuple[int, int]] = {
    'joint_2': (1, 0), 'spring_2': (0, 1), 'joint_3': (1, 0), 'spring_4': (0, 1),
}


def flexible_arm_urdf(
    link_length: float = DEFAULT_LINK_LENGTH,
    spring_offset: float = DEFAULT_SPRING_OFFSET,
    radius: float = DEFAULT_RADIUS,
    stiffness: float | npt.ArrayLike = DEFAULT_STIFFNESS,
) -> str:
    """URDF text of the 7-DOF flexible arm of Table 2 with its spring stiffness.

    Motors are ``joint_1``, ``joint_2``, ``joint_3`` (DH joints 1, 2, 5), virtual springs
    ``spring_1`` .. ``spring_4`` (DH joints 3, 4, 6, 7); all are revolute joints.

    Parameters
    ----------
    link_length : float
        Inflatable link length L [m].
    spring_offset : float
        l1 [m], ``0 < spring_offset < link_length``.
    radius : float
        Link radius [m] for the cylinder visuals.
    stiffness : float or array-like, shape (4,)
        Spring stiffness k [N m/rad] of eq. (7), one value for all springs (the paper's
        orthotropic assumption, section 2.3) or one per spring in ``SPRING_JOINT_NAMES`` order.

    Returns
    -------
    str
        URDF document, see ``dh_chain_urdf``.

    Raises
    ------
    ValueError
        If a length is invalid or the stiffness is not positive, finite, scalar or (4,).
    """
    table = flexible_dh_table(link_length, spring_offset)
    try:
        k = np.array(stiffness, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f'expected stiffness as a float or shape (4,) [N m/rad], got {stiffness!r}'
        ) from None
    if k.shape not in ((), (4,)):
        raise ValueError(f'expected stiffness of shape () or (4,), got {k.shape}')
    if not (np.isfinite(k).all() and (k > 0.0).all()):
        raise ValueError(
            f'expected stiffness to be positive and finite [N m/rad], got {stiffness!r}'
        )
    k = np.broadcast_to(k, (4,))
    # Link 1 is the bodies of joint_2 (l1, proximal cap) and spring_2 (l2, distal cap); link 2
    # those of joint_3 and spring_4.
    return dh_chain_urdf(
        'inflarm_flexible', table, FLEXIBLE_JOINT_NAMES, radius,
        dict(zip(SPRING_JOINT_NAMES, k.tolist(), strict=True)),
        caps=FLEXIBLE_CAPS,
    )


def spring_stiffness_from_urdf(text: str) -> dict[str, float]:
    """Read the ``<inflarm:spring>`` stiffness elements of a URDF document.

    Parameters
    ----------
    text : str
        URDF text, e.g. from ``flexible_arm_urdf`` or the ``robot_description`` parameter.

    Returns
    -------
    dict of str to float
        Stiffness k [N m/rad] per spring joint name, in document order; empty for a URDF
        without springs (the rigid arm).

    Raises
    ------
    ValueError
        If the text is not XML, an element lacks its attributes, names a joint that is not in
        the URDF or twice, or has a stiffness that is not positive and finite.
    """
    try:
        root = ET.fromstring(text)
    except (ET.ParseError, TypeError) as err:
        raise ValueError(f'expected text to be a URDF XML document: {err}') from None
    joints = {j.get('name') for j in root.iter('joint')}
    springs: dict[str, float] = {}
    for element in root.iter(f'{{{INFLARM_XMLNS}}}spring'):
        joint, value = element.get('joint'), element.get('stiffness')
        if joint is None or value is None:
            raise ValueError(
                'expected <inflarm:spring joint="..." stiffness="..."/>, '
                f'got attributes {element.attrib}'
            )
        if joint not in joints or joint in springs:
            raise ValueError(
                f'expected each spring joint once and declared as a <joint>, got {joint!r}'
            )
        springs[joint] = check_positive(f'stiffness of {joint!r}', value, 'N m/rad', 'stiffness')
    return springs


URDF_FILENAME = 'inflarm_flexible.urdf'


def main(argv: Sequence[str] | None = None) -> int:
    """Write the default arm's URDF to ``<directory>/inflarm_flexible.urdf``."""
    parser = argparse.ArgumentParser(
        description='Write the URDF of the default inflatable-link arm (flexible_arm_urdf()).')
    parser.add_argument('directory', type=Path, help='where to write ' + URDF_FILENAME)
    args = parser.parse_args(argv)
    args.directory.mkdir(parents=True, exist_ok=True)
    path = args.directory / URDF_FILENAME
    path.write_text(flexible_arm_urdf(), encoding='utf-8')
    print(path)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
