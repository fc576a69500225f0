"""sensor_msgs/JointState <-> arrays of the inflatable arm's joints, checked against the joint
table (``inflarm_model.urdf.JOINT_LIMITS``): the one place nodes read and write joint messages.
"""

from collections.abc import Sequence
import functools
import math

import numpy as np
import numpy.typing as npt
from sensor_msgs.msg import JointState

from inflarm_model.urdf import check_joint_positions
from inflarm_msgs_json.ros.problems import InputError


def joint_arrays(msg: JointState, names: Sequence[str], fields: Sequence[str] = ('position',),
                 optional: Sequence[str] = ()) -> dict[str, npt.NDArray[np.float64] | None]:
    """The values of ``names``, in that order, for each of ``fields`` of a joint state.

    Other joints in the message are ignored. Positions are checked against the joint limits.

    Parameters
    ----------
    msg : sensor_msgs.msg.JointState
    names : sequence of str
        Joints to read, e.g. ``FlexibleArm.MOTOR_JOINT_NAMES``.
    fields : sequence of str
        Fields that must be there: ``'position'``, ``'velocity'``, ``'effort'``.
    optional : sequence of str
        Fields read when the message has them (one value per name), else None.

    Returns
    -------
    dict
        Field name -> ndarray of shape (len(names),) [rad, rad/s, N·m], or None.

    Raises
    ------
    InputError
        Naming the problem: a missing or repeated joint, a field of the wrong length, a value
        that is not finite, a position outside its limits.
    """
    index = _joint_index(tuple(msg.name), tuple(names))
    arrays: dict[str, npt.NDArray[np.float64] | None] = {}
    for field in (*fields, *optional):
        values = getattr(msg, field)
        if len(values) == 0 and field in optional:
            arrays[field] = None
            continue
        if len(values) != len(msg.name):
            raise InputError('array length', f'{len(msg.name)} joint names but {len(values)} '
                                             f'{field} values')
        picked = [float(values[i]) for i in index]
        if not all(map(math.isfinite, picked)):
            raise InputError('not finite', f'{field} of {list(names)} is {picked}')
        arrays[field] = np.array(picked)
    if arrays.get('position') is not None:
        try:
            check_joint_positions(names, arrays['position'].tolist())
        except ValueError as error:
            raise InputError('joint limit', str(error)) from error
    return arrays


@functools.lru_cache(maxsize=64)
def _joint_index(given: tuple[str, ...], names: tuple[str, ...]) -> tuple[int, ...]:
    """Where each of ``names`` is in a message's ``given`` names: resolved once per layout."""
    repeated = sorted({n for n in given if given.count(n) > 1})
    if repeated:
        raise InputError('repeated joint', f'joints {repeated} appear more than once')
    missing = [n for n in names if n not in given]
    if missing:
        raise InputError('missing joint', f'expected joints {list(names)}, got {list(given)}')
    return tuple(given.index(n) for n in names)


def joint_state(names: Sequence[str], stamp=None, **fields: npt.ArrayLike) -> JointState:
    """A joint state of ``names`` with the given fields (position, velocity, effort)."""
    msg = JointState(name=list(names))
    if stamp is not None:
        msg.header.stamp = stamp
    for field, values in fields.items():
        if values is not None:
            setattr(msg, field, np.asarray(values, dtype=float).tolist())
    return msg
