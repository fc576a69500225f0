"""Parameters that describe the inflatable-link arm, shared by every node that models it.

All such nodes declare this one table, so a single YAML (``config/inflatable_arm.yaml``, keyed
``/**``) configures them alike. Geometry is structural (read-only); stiffness and link pressure
may change at runtime (a link re-inflated, a new characterization).
"""

import math

from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS
from inflarm_model.urdf import flexible_arm_urdf
from inflarm_msgs_json.ros.parameters import Parameter

ARM_PARAMETERS = (
    Parameter('arm.link_length_m', 0.6, 'inflatable link length L [m] (section 3)',
              range=(0.05, 10.0), read_only=True),
    Parameter('arm.spring_offset_m', 0.03,
              'virtual spring distance l1 from each link root [m] (section 4)',
              range=(0.001, 10.0), read_only=True),
    Parameter('arm.link_radius_m', 0.055, 'inflatable link radius r [m] (section 3)',
              range=(0.001, 1.0), read_only=True),
    Parameter('arm.spring_stiffness', [MEAN_STIFFNESS] * 4,
              'stiffness k of spring_1..spring_4 [N m/rad] (eq. 7; Table 3 mean)'),
    Parameter('arm.link_pressure_pa', [50000.0, 50000.0],
              'inflation pressure of link_1 and link_2 [Pa] (sets the wrinkling moment, eq. 3)'),
)


def check_arm_parameters(values: dict) -> str | None:
    """Why these arm parameter values are inconsistent, or None when they are fine.

    ``values`` maps parameter names to values; only the names present are checked.
    """
    length = values.get('arm.link_length_m')
    offset = values.get('arm.spring_offset_m')
    if length is not None and offset is not None and not offset < length:
        return f'arm.spring_offset_m ({offset} m) must be below arm.link_length_m ({length} m)'
    for name, count in (('arm.spring_stiffness', 4), ('arm.link_pressure_pa', 2)):
        value = values.get(name)
        if value is None:
            continue
        if len(value) != count or not all(math.isfinite(v) and v > 0.0 for v in value):
            return f'{name} must be {count} positive finite numbers, got {list(value)}'
    return None


def arm_from_parameters(values: dict) -> FlexibleArm:
    """The :class:`FlexibleArm` the parameter values describe."""
    return FlexibleArm(values['arm.link_length_m'], values['arm.spring_offset_m'])


def urdf_from_parameters(values: dict) -> str:
    """The URDF of the arm the parameter values describe (``inflarm_model.urdf``)."""
    return flexible_arm_urdf(
        link_length=values['arm.link_length_m'],
        spring_offset=values['arm.spring_offset_m'],
        radius=values['arm.link_radius_m'],
        stiffness=values['arm.spring_stiffness'],
    )

