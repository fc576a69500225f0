"""Parameters of the simulated plants, shared by the nodes that run them: the inflatable arm's
(``arm_sim`` and ``sim_mcu``) and the soft arm's (``sra_sim`` and ``sim_mcu``); one table, one
check, one constructor each.

The arm's geometry, stiffness and link pressures come with them from
``inflarm_model.nodes.arm_parameters`` (``ARM_PARAMETERS``, the shared ``inflatable_arm.yaml``).
"""

import dataclasses
import math

import numpy as np

from inflarm_hw.inflatable_arm_sim import ArmSimParams, InflatableArmSim
from inflarm_hw.nodes.camera_publisher import camera_from_parameters
from inflarm_hw.sra_plant import (
    PLANT_PARAMETER_DESCRIPTIONS,
    PLANT_PARAMETER_NAMES,
    PlantParameterError,
    SoftArmPlantParams,
)
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    arm_from_parameters,
    check_arm_parameters,
)
from inflarm_model.urdf import check_joint_positions
from inflarm_msgs_json.ros.parameters import Parameter

MAX_TIP_FORCE_N = 500.0  # beyond this the links buckle long before: no equilibrium to simulate

ARM_PLANT_PARAMETERS = ARM_PARAMETERS + (
    Parameter('tip_force_n', [0.0, 10.0, -15.0],
              'external tip load [N], base frame (default: the sample load of section 4); '
              'may change at runtime'),
    Parameter('initial_motor_positions_rad', [0.0, 0.6, -1.2],
              'joint_1..joint_3 at start [rad]', read_only=True),
    Parameter('motor.time_constant_s', 0.1, 'motor position time constant [s]',
              range=(0.001, 10.0), read_only=True),
    Parameter('motor.max_velocity_rad_s', 1.0, 'motor rate limit [rad/s]', range=(0.01, 100.0),
              read_only=True),
    Parameter('noise.position_rad', 1e-4, 'motor angle noise (std) [rad]', range=(0.0, 0.1)),
    Parameter('noise.effort_nm', 0.02, 'motor torque noise (std) [N m]', range=(0.0, 10.0)),
    Parameter('wrinkling', False, 'saturate link moments at M_max (Table 3)', read_only=True),
)
_NOISE_FIELDS = {'noise.position_rad': 'position_noise', 'noise.effort_nm': 'effort_noise'}


def check_arm_plant_parameters(values: dict) -> str | None:
    """Why these parameter values are not an arm to simulate, or None (checks those given)."""
    problem = check_arm_parameters(values)
    if problem is not None:
        return problem
    force = values.get('tip_force_n')
    if force is not None:
        if len(force) != 3 or not all(math.isfinite(v) for v in force):
            return f'tip_force_n must be 3 finite numbers, got {list(force)}'
        if math.hypot(*force) > MAX_TIP_FORCE_N:
            return f'tip_force_n {list(force)} is over {MAX_TIP_FORCE_N:.0f} N'
    start = values.get('initial_motor_positions_rad')
    if start is not None:
        if len(start) != 3:
            return f'initial_motor_positions_rad must be 3 numbers, got {list(start)}'
        try:
            check_joint_positions(FlexibleArm.MOTOR_JOINT_NAMES, start)
        except ValueError as error:
            return f'initial_motor_positions_rad: {error}'
    return None


def arm_plant_from_parameters(p: dict, rng: np.random.Generator) -> InflatableArmSim:
    """The simulated arm the (checked) parameter values ``p`` describe, under its tip load."""
    sim = InflatableArmSim(
        arm_from_parameters(p), p['arm.spring_stiffness'], p['arm.link_pressure_pa'],
        p['arm.link_radius_m'], p['initial_motor_positions_rad'],
        ArmSimParams(motor_time_constant=p['motor.time_constant_s'],
                     motor_max_velocity=p['motor.max_velocity_rad_s'],
                     position_noise=p['noise.position_rad'],
                     effort_noise=p['noise.effort_nm'], wrinkling=p['wrinkling']), rng)
    sim.set_tip_force(p['tip_force_n'])
    return sim


def apply_arm_plant_parameter(sim: InflatableArmSim, name: str, value) -> str | None:
    """Apply one runtime change to ``sim``; a line to log, or None if ``name`` is not one."""
    if name == 'tip_force_n':
        sim.set_tip_force(value)
        return f'tip load now {list(value)} N'
    if name == 'arm.spring_stiffness':
        sim.set_stiffness(value)
        return f'spring stiffness now {list(value)} N m/rad'
    if name == 'arm.link_pressure_pa':
        sim.set_link_pressure(value)
        return f'link pressures now {list(value)} Pa'
    if name in _NOISE_FIELDS:
        sim.params = dataclasses.replace(sim.params, **{_NOISE_FIELDS[name]: value})
        return None
    return None


# -- the soft arm (sra_sim, sim_mcu) ---------------------------------------------------------

_SRA = SoftArmPlantParams()
# no ranges here: SoftArmPlantParams is the one check of the plant's constants
SRA_PLANT_PARAMETERS = tuple(
    Parameter(name, float(getattr(_SRA, field)), PLANT_PARAMETER_DESCRIPTIONS[field],
              read_only=True)
    for field, name in PLANT_PARAMETER_NAMES.items())
"""The soft-arm plant's physical constants, ``plant.*`` (`PLANT_PARAMETER_NAMES`): an
identified plant loads with ``--params-file`` (``inflarm-identify-plant``)."""
# the fields with parameters outside plant.*, for error messages naming the parameter
_SRA_OTHER_NAMES = {'noise_center_px': 'measurement_noise.center_px',
                    'noise_radius_px': 'measurement_noise.radius_px'}


def sra_plant_from_parameters(values: dict) -> SoftArmPlantParams:
    """The soft-arm plant the parameter values ``values`` (by ROS name: ``plant.*``,
    ``measurement_noise.*``, ``camera.*``) describe.

    Raises
    ------
    ValueError
        Naming the ROS parameter whose value the plant rejects.
    """
    fields = {field: values[name] for field, name in PLANT_PARAMETER_NAMES.items()}
    try:
        return SoftArmPlantParams(
            **fields, noise_center_px=values['measurement_noise.center_px'],
            noise_radius_px=values['measurement_noise.radius_px'],
            camera=camera_from_parameters(values))
    except PlantParameterError as error:
        name = {**PLANT_PARAMETER_NAMES, **_SRA_OTHER_NAMES}.get(error.field, error.field)
        raise ValueError(f"parameter '{name}': {error}") from error
