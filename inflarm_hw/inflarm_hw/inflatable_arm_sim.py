"""Simulated inflatable-link arm: position-controlled motors, links deflecting under a tip load.

The simulation backend behind the ``arm_sim`` node (pure numpy/Pinocchio, no rclpy). Motors
follow position commands as first-order lags with a rate limit, their targets clamped to the
motor limits of ``inflarm_model.urdf.JOINT_LIMITS`` (those of the URDF); the links sit at the
elastostatic equilibrium of the tip load (``inflarm_model.elastostatics``, eqs 5-7 of
000_ce37cf035a0a87c6), re-solved every step from the previous deflection. With ``wrinkling``
on, a link whose bending moment would exceed M_max (Table 3) yields: its springs soften until
the moment sits at M_max, as the measured characteristic of Fig 9 saturates.

Sensors report what the estimator consumes: motor angles, velocities and the load torques on
the motor axes (tau_m = U_m^T f, eq. 6, in ``inflarm_model.elastostatics``' convention), with
optional Gaussian noise; the true tip and spring deflections are kept for evaluation.
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from inflarm_model.elastostatics import (
    check_stiffness,
    link_moments,
    motor_torques,
    spring_deflections,
)
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import TABLE3, wrinkling_moment
from inflarm_model.urdf import JOINT_LIMITS, MOTOR_JOINT_NAMES, MOTOR_MAX_VELOCITY

# Position limits of the motors [rad], DH joints 1, 2, 5: the URDF's.
MOTOR_LOWER, MOTOR_UPPER = np.array([JOINT_LIMITS[name] for name in MOTOR_JOINT_NAMES]).T

# A wrinkled link's springs soften, pass after pass, until its moment is within
# _WRINKLE_TOLERANCE of M_max: the load's lever arm shrinks as the link yields.
_WRINKLE_PASSES = 50
_WRINKLE_TOLERANCE = 1e-4


@dataclass(frozen=True)
class ArmSimParams:
    """Constants of the simulated arm.

    Attributes
    ----------
    motor_time_constant : float
        Time constant of each motor's position response [s].
    motor_max_velocity : float
        Rate limit of each motor [rad/s] (the URDF's velocity limit by default).
    position_noise : float
        Standard deviation of the motor angle readings [rad].
    effort_noise : float
        Standard deviation of the motor torque readings [N·m].
    wrinkling : bool
        Saturate each link's bending moment at M_max(p) (Table 3).
    """

    motor_time_constant: float = 0.1
    motor_max_velocity: float = MOTOR_MAX_VELOCITY
    position_noise: float = 0.0
    effort_noise: float = 0.0
    wrinkling: bool = False

    def __post_init__(self) -> None:
        for name in ('motor_time_constant', 'motor_max_velocity'):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0.0):
                raise ValueError(f'expected {name} > 0, got {getattr(self, name)}')
        for name in ('position_noise', 'effort_noise'):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0.0):
                raise ValueError(f'expected {name} >= 0, got {getattr(self, name)}')


@dataclass(frozen=True)
class ArmSimState:
    """One sample of the simulated arm (arrays in DH motor/spring order).

    Attributes
    ----------
    time : float
        Simulated time [s].
    q_m, dq_m : ndarray, shape (3,)
        Motor angles [rad] as measured (noisy) and velocities [rad/s].
    tau_m : ndarray, shape (3,)
        Motor-axis load torques [N·m] as measured (noisy).
    q_k : ndarray, shape (4,)
        True spring deflections [rad].
    tip_position : ndarray, shape (3,)
        True deflected tip position [m], base frame.
    link_moments : ndarray, shape (2,)
        Bending moment on link 1 and link 2 [N·m].
    wrinkled : ndarray of bool, shape (2,)
        Links held at M_max (only with ``wrinkling``).
    """

    time: float
    q_m: npt.NDArray[np.float64]
    dq_m: npt.NDArray[np.float64]
    tau_m: npt.NDArray[np.float64]
    q_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    link_moments: npt.NDArray[np.float64]
    wrinkled: npt.NDArray[np.bool_]


def max_moment(pressure: float, radius: float) -> float:
    """M_max [N·m] at ``pressure`` [Pa]: Table 3's ratio M_max / M_w, interpolated over the
    tested pressures (held beyond them), times M_w(p) of eq. (3)."""
    rows = [row for row in TABLE3 if row.max_moment is not None]
    ratio = np.interp(pressure, [r.pressure for r in rows],
                      [r.max_moment / r.wrinkling_moment for r in rows])
    return float(ratio * wrinkling_moment(pressure, radius))


class InflatableArmSim:
    """The arm of Table 2 under a tip load, stepped in time.

    Parameters
    ----------
    arm : FlexibleArm
        Kinematics.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].
    link_pressure : array-like, shape (2,)
        Inflation pressure of link 1 and link 2 [Pa] (for the wrinkling saturation).
    link_radius : float
        Link radius [m].
    q_m0 : array-like, shape (3,)
        Initial motor angles [rad], within the motor limits; also the initial command.
    params : ArmSimParams
    rng : numpy.random.Generator, optional
        Source of the sensor noise.
    """

    def __init__(self, arm: FlexibleArm, stiffness: npt.ArrayLike, link_pressure: npt.ArrayLike,
                 link_radius: float, q_m0: npt.ArrayLike,
                 params: ArmSimParams = ArmSimParams(),  # noqa: B008 (frozen)
                 rng: np.random.Generator | None = None) -> None:
        self.arm = arm
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng()
        self.set_stiffness(stiffness)
        self.link_radius = float(link_radius)
        self.set_link_pressure(link_pressure)
        self.q_m = _finite('q_m0', q_m0, 3)
        if not ((self.q_m >= MOTOR_LOWER) & (self.q_m <= MOTOR_UPPER)).all():
            raise ValueError(f'expected q_m0 within the motor limits {MOTOR_LOWER.tolist()} .. '
                             f'{MOTOR_UPPER.tolist()} rad, got {self.q_m.tolist()}')
        self.dq_m = np.zeros(3)
        self.target = self.q_m.copy()
        self.feed_forward = np.zeros(3)
        self.force = np.zeros(3)
        self.q_k = np.zeros(4)
        self.wrinkled = np.zeros(2, dtype=bool)
        self.time = 0.0
        self._settle()

    def set_stiffness(self, stiffness: npt.ArrayLike) -> None:
        """Spring stiffness [N·m/rad], scalar or (4,)."""
        self.stiffness = np.array(check_stiffness(stiffness))

    def set_link_pressure(self, link_pressure: npt.ArrayLike) -> None:
        """Inflation pressures of link 1 and link 2 [Pa], positive."""
        pressure = _finite('link_pressure', link_pressure, 2)
        if not (pressure > 0.0).all():
            raise ValueError(f'expected link_pressure > 0 Pa, got {pressure.tolist()}')
        self.m_max = np.array([max_moment(p, self.link_radius) for p in pressure])

    def set_tip_force(self, force: npt.ArrayLike) -> None:
        """External tip force [N], base frame; the links settle to it at the next step."""
        self.force = _finite('force', force, 3)

    def command(self, q_m: npt.ArrayLike, dq_m: npt.ArrayLike | None = None) -> None:
        """New motor position targets [rad], clamped to the motor limits (``JOINT_LIMITS``),
        with an optional velocity feed-forward [rad/s] (default 0): the target then moves on
        at that velocity until the next command, and the velocity is added to each motor's
        position loop, as a servo drive interpolates position-and-velocity set points."""
        self.target = np.clip(_finite('q_m', q_m, 3), MOTOR_LOWER, MOTOR_UPPER)
        self.feed_forward = np.zeros(3) if dq_m is None else _finite('dq_m', dq_m, 3)

    def step(self, dt: float) -> ArmSimState:
        """Advance ``dt`` seconds and return the new sample."""
        if not (np.isfinite(dt) and dt > 0.0):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        p = self.params
        velocity = self.feed_forward + (self.target - self.q_m) / max(p.motor_time_constant, dt)
        velocity = np.clip(velocity, -p.motor_max_velocity, p.motor_max_velocity)
        self.q_m = self.q_m + velocity * dt
        # The target moves on at the feed-forward velocity: at the end of the step it is where
        # the set point is due then, and a motor on it stays on it.
        self.target = np.clip(self.target + self.feed_forward * dt, MOTOR_LOWER, MOTOR_UPPER)
        self.dq_m = velocity
        self.time += dt
        self._settle()
        return self.state()

    def _settle(self) -> None:
        """Spring deflections at equilibrium with the current motors and load."""
        stiffness = self.stiffness.copy()
        self.wrinkled[:] = False
        for _ in range(_WRINKLE_PASSES):
            result = spring_deflections(self.arm, self.q_m, self.force, stiffness,
                                        q_k0=self.q_k)
            if not result.converged:
                raise RuntimeError(
                    f'the arm has no stable equilibrium under {self.force.tolist()} N '
                    f'({result.status}); reduce the load')
            self.q_k = result.q_k
            if not self.params.wrinkling:
                return
            moments = self.link_moments()
            over = moments > self.m_max * (1.0 + _WRINKLE_TOLERANCE)
            if not over.any():
                return
            for link in np.flatnonzero(over):
                stiffness[2 * link:2 * link + 2] *= self.m_max[link] / moments[link]
            self.wrinkled |= over

    def q(self) -> npt.NDArray[np.float64]:
        """True joint angles, shape (7,), DH order."""
        return FlexibleArm.assemble_q(self.q_m, self.q_k)

    def link_moments(self) -> npt.NDArray[np.float64]:
        """Bending moment on link 1 and link 2 [N·m] (``inflarm_model.elastostatics``)."""
        return link_moments(self.arm, self.q(), self.force)

    def state(self) -> ArmSimState:
        p = self.params
        q = self.q()
        return ArmSimState(
            time=self.time,
            q_m=self.q_m + self.rng.normal(0.0, p.position_noise, 3),
            dq_m=self.dq_m.copy(),
            tau_m=motor_torques(self.arm, q, self.force) + self.rng.normal(0.0, p.effort_noise, 3),
            q_k=self.q_k.copy(),
            tip_position=self.arm.fk(q)[:3, 3],
            link_moments=self.link_moments(),
            wrinkled=self.wrinkled.copy(),
        )


def _finite(name: str, value: npt.ArrayLike, n: int) -> npt.NDArray[np.float64]:
    array = np.asarray(value, dtype=float)
    if array.shape != (n,) or not np.isfinite(array).all():
        raise ValueError(
            f'expected {name} as {n} finite numbers, got {np.asarray(value).tolist()}')
    return array.copy()
