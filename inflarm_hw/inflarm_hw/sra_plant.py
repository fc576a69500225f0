"""Simulated pneumatic soft robot arm (SRA): valves, chambers and end point, batched over arms.

The simulation backend for the SRA of ``001_b59ad71c956a1751`` (sections 2-3). It stands in for
the five ITV2050 proportional valves, the chambers of PEA1&2 (one pressure through the T-pipe) and
bellows B1-B4, and the arm's mechanics, so that the model-free PID + ILC controller of section 3
has the same kind of work to do as on the prototype: a slow, large PEA chamber, fast bellows, the
valves' 0-4 kPa dead zone, backlash-like hysteresis and the coupling of bending into z.

Everything is vectorized over a leading axis of ``n`` independent arms (``n = 1`` for the ROS
node, thousands for building the experiential knowledge database); there is no Python loop over
arms. Pure numpy, no rclpy.

Signal chain per arm and chamber (``CHAMBERS`` order: PEA, B1, B2, B3, B4)::

    command [Pa] -> valve voltage (eq. 2) -> transport delay (dead time)
      -> valve output [Pa] (dead zone, range; both in `inflarm_hw.valve`)
      -> chamber pressure (first order, time constant growing with chamber volume)
      -> static extension / bend (saturating, bellows stiff below a threshold pressure)
      -> play operator (hysteresis) -> mechanics (extension: 2nd order; bend: 1st order)
      -> end point by the point-joint kinematics of eq. (6) (`inflarm_model.soft_arm`)

Bend directions follow Fig 4 (see `inflarm_model.soft_arm.BELLOWS_PUSH`): B4 bends the end
towards +x, B2 towards -x, B3 towards +y, B1 towards -y, so Q1 = B3 + B4, Q2 = B2 + B3,
Q3 = B1 + B2, Q4 = B1 + B4. Bending lowers z (``z = l1 (1 + cos(theta))``), which is the x/z
coupling the paper's z controller has to fight. With all chambers at 0 Pa the arm rests straight
at ``(0, 0, 0.604)`` m, the initial point of the Fig 7 experiment, so a trial starts from the
paper's initial output of 0 kPa (eq. 3).

By default the valves act 0.1 s after their command and `SoftArmPlant.measure` adds 0.5 mm of
noise per axis (`SoftArmPlantParams`); `NOISE_FREE` keeps the delay and measures exactly
(deterministic trials), `IDEAL` has neither (instantaneous valves, exact measurements).
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from inflarm_hw.valve import ITV2050, ValveModel, pressure_to_voltage, voltage_to_pressure
from inflarm_model.soft_arm import CHAMBERS, inverse_kinematics

_N_CHAMBERS = len(CHAMBERS)


@dataclass(frozen=True)
class SoftArmPlantParams:
    """Constants of the simulated SRA. Values are chosen, not identified (the paper gives no
    plant model); the reasons are given per constant.

    Attributes
    ----------
    pea_rest_length : float
        Length of PEA1 (= PEA2) at 0 Pa [m]. 0.302 m puts the straight arm at z = 0.604 m, the
        initial point of Fig 7, and makes the fully bent rest arm reach z ~ 0.57 m, the lower
        bound of the positive-pressure work space (Fig 5A).
    extension_max : float
        Asymptotic extension of each PEA at infinite pressure [m]. 0.223 m makes the straight arm
        reach z = 0.990 m (top of Fig 5A) at 100 kPa.
    extension_pressure_scale : float
        Pressure scale of the saturating extension law
        ``ext = extension_max (1 - exp(-p / scale))`` [Pa]. 50 kPa: stiffening origami PEA, the
        Fig 7 target (z = 0.670 m) needs about 13 kPa, the same order as Fig 4's 20 kPa.
    bend_max : float
        Asymptotic bend angle produced by one bellows [rad]. 0.45 rad (26 deg) gives
        |x| ~ 0.2 m at full extension, the X bound of Fig 5A.
    bend_pressure_scale : float
        Pressure scale of ``bend = bend_max (1 - exp(-(p - threshold) / scale))`` [Pa]. 25 kPa:
        the Fig 7 target needs about 25-30 kPa in each of its two bellows.
    bellows_threshold : float
        Pressure below which a bellows does not bend the PBA [Pa]. 2 kPa: the "stiffness of the
        four bellows at low chamber pressure" blamed for oscillation near x = y = 0 (4.3.2).
    bend_skew : float
        Rotation of the bend vector about +z from bellows misalignment [rad]. 0.03 rad (1.7 deg)
        couples x and y weakly, as on a hand-assembled PBA.
    pea_time_constant : float
        Time constant of the PEA1&2 chamber pressure at rest length [s]. It grows with the chamber
        volume, i.e. with ``l1 / pea_rest_length``: 1.2 s at rest, ~1.4 s at the Fig 7 target and
        ~2 s fully extended ("the large chamber volume of PEA1&2", 3.3).
    bellows_time_constant : float
        Time constant of a bellows chamber pressure when unbent [s]. 0.25 s (small chambers).
    bellows_volume_gain : float
        Relative growth of a bellows' time constant at full bend (its volume grows as it
        lengthens) [-]. 0.5: 0.25 s -> 0.375 s.
    extension_natural_frequency : float
        Natural angular frequency of the axial mechanics (mass of PEA2, PBA and end on the PEA
        stiffness) [rad/s]. 3 rad/s (0.48 Hz): slow enough to show the z oscillation of Fig 7.
    extension_damping : float
        Damping ratio of the axial mechanics [-]. 0.5: visible overshoot, dies out in a few s.
    bend_time_constant : float
        First-order lag of the bend behind its static value [s]. 0.15 s.
    extension_play : float
        Half-width of the play (backlash) operator on the extension [m]. 1.5 mm (about 3 mm in
        z, both PEAs): soft-material hysteresis of about 1 % of the stroke, below the 5 mm
        accuracy the paper reports so that the arm can settle within it.
    bend_play : float
        Half-width of the play operator on each bend component [rad]. 0.005 rad, about 2 mm at
        the end.
    valve : inflarm_hw.valve.ValveModel
        The five proportional valves (eq. (2), dead zone, range): by default the ITV2050's
        0.005-0.9 MPa over 0-10 V and the "dead zone of the proportional valves at 0-4 kPa"
        (4.3.2).
    max_substep : float
        Largest internal integration step [s]; a ``step(dt)`` is split into equal substeps no
        longer than this. 0.05 s (4 substeps at 5 Hz) keeps the axial oscillator
        (omega h = 0.15) accurate; pressures are integrated exactly per substep.
    valve_delay : float
        Transport delay (dead time) between a command and the valves' output [s]: a command
        given at ``t`` sets the valve outputs from ``t + valve_delay`` on. 0.1 s: the response
        time class of electro-pneumatic regulators of the ITV2050's size (their catalogue
        response time without load is of this order; the prototype's valves were not
        characterized in the paper), of which the pressure wave's travel along ~2 m of tubing
        (~6 ms at the speed of sound) is a small part. These are the "various unavoidable
        delays in the control system" of section 3.1 that the controller has to cope with.
        0 gives the ideal, instantaneous valves.
    noise_std : float
        Standard deviation of the vision noise added per axis by `SoftArmPlant.measure` [m].
        0.5 mm by default: the spread of the simulated camera + tracker over the work space
        (median 3D error 0.6 mm, `inflarm_vision/README.md`), for callers that measure the end
        point without rendering images. 0 for deterministic trials (`NOISE_FREE`).
    """

    pea_rest_length: float = 0.302
    extension_max: float = 0.223
    extension_pressure_scale: float = 50e3
    bend_max: float = 0.45
    bend_pressure_scale: float = 25e3
    bellows_threshold: float = 2e3
    bend_skew: float = 0.03
    pea_time_constant: float = 1.2
    bellows_time_constant: float = 0.25
    bellows_volume_gain: float = 0.5
    extension_natural_frequency: float = 3.0
    extension_damping: float = 0.5
    bend_time_constant: float = 0.15
    extension_play: float = 0.0015
    bend_play: float = 0.005
    valve: ValveModel = ITV2050
    max_substep: float = 0.05
    valve_delay: float = 0.1
    noise_std: float = 0.5e-3

    def __post_init__(self) -> None:
        if not isinstance(self.valve, ValveModel):
            raise ValueError(f'expected valve a ValveModel, got {type(self.valve).__name__}')
        for name, value in vars(self).items():
            if name != 'valve' and not np.isfinite(value):
                raise ValueError(f'expected finite {name}, got {value}')
        positive = (
            'pea_rest_length', 'extension_max', 'extension_pressure_scale', 'bend_max',
            'bend_pressure_scale', 'pea_time_constant', 'bellows_time_constant',
            'extension_natural_frequency', 'extension_damping', 'bend_time_constant',
            'max_substep')
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ValueError(f'expected {name} > 0, got {getattr(self, name)}')
        non_negative = ('bellows_threshold', 'bellows_volume_gain', 'extension_play',
                        'bend_play', 'valve_delay', 'noise_std')
        for name in non_negative:
            if getattr(self, name) < 0.0:
                raise ValueError(f'expected {name} >= 0, got {getattr(self, name)}')


NOISE_FREE = SoftArmPlantParams(noise_std=0.0)
"""The default plant (valve delay included) with exact measurements: deterministic trials."""

IDEAL = SoftArmPlantParams(valve_delay=0.0, noise_std=0.0)
"""Instantaneous valves and exact measurements (the simulated plant before the valve delay)."""


class SoftArmPlant:
    """``n`` independent simulated SRAs stepped together.

    Parameters
    ----------
    n : int
        Number of arms (leading axis of every state array).
    params : SoftArmPlantParams
        Plant constants.
    rng : numpy.random.Generator, optional
        Source of the measurement noise of `measure` (only used if ``params.noise_std > 0``).
    """

    def __init__(
        self,
        n: int = 1,
        params: SoftArmPlantParams = SoftArmPlantParams(),  # noqa: B008 (frozen, immutable)
        rng: np.random.Generator | None = None,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f'expected n an integer >= 1, got {n!r}')
        self.n = int(n)
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng()
        self.reset()

    @property
    def params(self) -> SoftArmPlantParams:
        """Plant constants; assigning new ones (e.g. another noise level) keeps the state."""
        return self._params

    @params.setter
    def params(self, params: SoftArmPlantParams) -> None:
        if not isinstance(params, SoftArmPlantParams):
            raise ValueError(f'expected params a SoftArmPlantParams, got {type(params).__name__}')
        self._params = params
        c, s = np.cos(params.bend_skew), np.sin(params.bend_skew)
        # bend per bellows B1..B4 -> bend vector (bx, by): B4 - B2 along x, B3 - B1 along y
        # (each bellows bends away from its own side), then rotated by the skew
        self._bend_matrix = np.array([[s, -c], [-c, -s], [-s, c], [c, s]])
        self._play_width = np.array([params.extension_play, params.bend_play, params.bend_play])
        self._tau_bellows_gain = (params.bellows_time_constant * params.bellows_volume_gain
                                  / params.bend_max)

    # -- state ---------------------------------------------------------------------------------

    def reset(self, end_point: npt.ArrayLike | None = None) -> None:
        """Put every arm at rest, or at steady state holding ``end_point``.

        Parameters
        ----------
        end_point : array-like, shape (3,) or (n, 3), optional
            Point to hold, in ``sra_mount`` [m]. The chambers are set to `holding_pressures`,
            the mechanics to rest at that point and the hysteresis centred on it.
            ``None`` (default): all chambers at 0 Pa, straight arm at ``(0, 0, 0.604)`` m.
        """
        n = self.n
        pressures = None if end_point is None else self.holding_pressures(end_point)
        self.time = 0.0
        self._pressure = np.zeros((n, _N_CHAMBERS))
        # valve outputs now [Pa], and the commanded ones still in the delay line:
        # (time they reach the valve outputs [s], outputs (n, 5) [Pa]), oldest first
        self._valve_output = np.zeros((n, _N_CHAMBERS))
        self._pending: list[tuple[float, npt.NDArray[np.float64]]] = []
        self._tau = np.empty((n, _N_CHAMBERS))
        self._bellows = np.zeros((n, 4))  # static bend per bellows B1..B4 [rad]
        self._shape = np.zeros((n, 3))  # static (extension [m], bx, by [rad])
        self._shape_play = np.zeros((n, 3))  # the same after the play operator
        self._extension = np.zeros(n)
        self._extension_rate = np.zeros(n)
        self._bend = np.zeros((n, 2))
        if pressures is None:
            return
        self._pressure[:] = pressures
        self._valve_output[:] = pressures  # the valves have been holding them
        self._update_static_shape()
        self._shape_play[:] = self._shape
        self._extension[:] = self._shape[:, 0]
        self._bend[:] = self._shape[:, 1:]

    @property
    def chamber_pressures(self) -> npt.NDArray[np.float64]:
        """Chamber pressures, shape (n, 5), in `CHAMBERS` order [Pa] (a copy)."""
        return self._pressure.copy()

    @property
    def valve_outputs(self) -> npt.NDArray[np.float64]:
        """Pressures the valves deliver now, shape (n, 5), in `CHAMBERS` order [Pa] (a copy):
        the command of ``params.valve_delay`` ago through eq. (2) and the dead zone."""
        return self._valve_output.copy()

    @property
    def end_point(self) -> npt.NDArray[np.float64]:
        """True end point of every arm, shape (n, 3), in ``sra_mount`` [m]."""
        p = self.params
        l1 = p.pea_rest_length + self._extension
        theta = np.hypot(self._bend[:, 0], self._bend[:, 1])
        # sin(theta) / theta, finite at theta = 0
        lateral = l1 * np.sinc(theta / np.pi)
        return np.stack([lateral * self._bend[:, 0], lateral * self._bend[:, 1],
                         l1 * (1.0 + np.cos(theta))], axis=-1)

    def measure(self) -> npt.NDArray[np.float64]:
        """End point as the vision system sees it, shape (n, 3) [m]: `end_point` plus
        independent Gaussian noise of ``params.noise_std`` per axis."""
        if self.params.noise_std == 0.0:
            return self.end_point
        return self.end_point + self.rng.normal(0.0, self.params.noise_std, (self.n, 3))

    # -- valves, eq. (2) (inflarm_hw.valve) ----------------------------------------------------

    def valve_voltage(self, pressure: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Control voltage that asks a valve for ``pressure`` [Pa], any shape: eq. (2) inverted,
        clamped to the valve's input range [V] (`inflarm_hw.valve.pressure_to_voltage`)."""
        return pressure_to_voltage(pressure, self.params.valve)

    def valve_pressure(self, voltage: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Output pressure of a valve for a control voltage [V], any shape: eq. (2) plus the
        dead zone [Pa] (`inflarm_hw.valve.voltage_to_pressure`)."""
        return voltage_to_pressure(voltage, self.params.valve)

    # -- statics -------------------------------------------------------------------------------

    def _static_shape(
        self, pressures: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(extension [m], bend vector (..., 2) [rad], bend per bellows (..., 4) [rad])."""
        p = self.params
        extension = p.extension_max * -np.expm1(pressures[..., 0] / -p.extension_pressure_scale)
        over = np.maximum(pressures[..., 1:] - p.bellows_threshold, 0.0)
        bellows = p.bend_max * -np.expm1(over / -p.bend_pressure_scale)
        return extension, bellows @ self._bend_matrix, bellows

    def _update_static_shape(self) -> None:
        extension, bend, self._bellows = self._static_shape(self._pressure)
        self._shape[:, 0] = extension
        self._shape[:, 1:] = bend

    def static_end_point(self, pressures: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """End point at steady state under constant chamber pressures, ignoring hysteresis.

        Parameters
        ----------
        pressures : array-like, shape (5,) or (..., 5)
            Chamber pressures in `CHAMBERS` order [Pa], non-negative.

        Returns
        -------
        end_point : ndarray, shape (3,) or (..., 3)
            In ``sra_mount`` [m]. Steady states reached through the hysteresis lie within
            ``extension_play`` and ``bend_play`` of it.
        """
        pr = np.asarray(pressures, dtype=float)
        if pr.ndim == 0 or pr.shape[-1] != _N_CHAMBERS:
            raise ValueError(f'expected pressures of shape (5,) or (..., 5), got {pr.shape}')
        if not np.all(np.isfinite(pr)) or np.any(pr < 0.0):
            raise ValueError(f'expected finite non-negative pressures [Pa], got {pr}')
        extension, bend, _ = self._static_shape(pr)
        l1 = self.params.pea_rest_length + extension
        theta = np.hypot(bend[..., 0], bend[..., 1])
        lateral = l1 * np.sinc(theta / np.pi)
        return np.stack([lateral * bend[..., 0], lateral * bend[..., 1],
                         l1 * (1.0 + np.cos(theta))], axis=-1)

    def holding_pressures(self, end_point: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Chamber pressures whose static shape is ``end_point`` (inverse of `static_end_point`).

        Only the two bellows of the target's quadrant are inflated (Fig 4); the others are 0.

        Parameters
        ----------
        end_point : array-like, shape (3,) or (n, 3)
            Point in ``sra_mount`` [m].

        Returns
        -------
        pressures : ndarray, shape (n, 5)
            In `CHAMBERS` order [Pa].

        Raises
        ------
        ValueError
            If the simulated arm cannot hold the point (too short, too long or bent too far).
        """
        pt = np.asarray(end_point, dtype=float)
        if pt.shape not in ((3,), (self.n, 3)):
            raise ValueError(f'expected end_point of shape (3,) or ({self.n}, 3), got {pt.shape}')
        pt = np.broadcast_to(pt, (self.n, 3))
        p = self.params
        config = inverse_kinematics(pt)
        extension = np.asarray(config.pea_length) - p.pea_rest_length
        if np.any(extension < 0.0) or np.any(extension >= p.extension_max):
            raise ValueError(
                f'end_point needs a PEA length outside the simulated range '
                f'[{p.pea_rest_length:.3f}, {p.pea_rest_length + p.extension_max:.3f}) m')
        pressures = np.zeros((self.n, _N_CHAMBERS))
        pressures[:, 0] = -p.extension_pressure_scale * np.log1p(-extension / p.extension_max)
        theta = np.asarray(config.bend_angle)
        phi = np.asarray(config.bend_direction) - p.bend_skew
        bx, by = theta * np.cos(phi), theta * np.sin(phi)
        need = np.zeros((self.n, 4))  # bend per bellows B1..B4
        need[:, 3] = np.maximum(bx, 0.0)
        need[:, 1] = np.maximum(-bx, 0.0)
        need[:, 2] = np.maximum(by, 0.0)
        need[:, 0] = np.maximum(-by, 0.0)
        if np.any(need >= p.bend_max):
            raise ValueError(
                f'end_point needs a bend beyond the simulated bellows limit {p.bend_max:.3f} rad')
        active = need > 0.0
        pressures[:, 1:] = np.where(
            active,
            p.bellows_threshold - p.bend_pressure_scale * np.log1p(-need / p.bend_max),
            0.0)
        return pressures

    # -- dynamics ------------------------------------------------------------------------------

    def step(self, pressure_command: npt.ArrayLike, dt: float) -> None:
        """Apply valve set pressures for ``dt`` seconds.

        Parameters
        ----------
        pressure_command : array-like, shape (n, 5) or (5,)
            Set pressure of each valve in `CHAMBERS` order [Pa] (a (5,) command goes to every
            arm). Turned into valve voltages by eq. (2) (`step_valve_voltages`).
        dt : float
            Duration [s], > 0; integrated in substeps of at most ``params.max_substep``.
        """
        cmd = np.asarray(pressure_command, dtype=float)
        if cmd.shape not in ((self.n, _N_CHAMBERS), (_N_CHAMBERS,)):
            raise ValueError(
                f'expected pressure_command of shape ({self.n}, 5) or (5,), got {cmd.shape}')
        if not np.isfinite(cmd).all():
            raise ValueError('expected finite pressure_command [Pa]')
        self.step_valve_voltages(self.valve_voltage(cmd), dt)

    def step_valve_voltages(self, voltages: npt.ArrayLike, dt: float) -> None:
        """Drive the valves at control voltages for ``dt`` seconds (what an MCU's DACs do).

        Parameters
        ----------
        voltages : array-like, shape (n, 5) or (5,)
            Control voltage of each valve in `CHAMBERS` order [V]. From ``params.valve_delay``
            after now on, each valve delivers eq. (2) of it (clamped to its input range, 0 Pa
            in the dead zone) until the next command arrives, and its chamber's pressure
            follows that output.
        dt : float
            Duration [s], > 0; integrated in substeps of at most ``params.max_substep``.
        """
        u = np.asarray(voltages, dtype=float)
        if u.shape not in ((self.n, _N_CHAMBERS), (_N_CHAMBERS,)):
            raise ValueError(
                f'expected voltages of shape ({self.n}, 5) or (5,), got {u.shape}')
        if not np.isfinite(u).all():
            raise ValueError('expected finite voltages [V]')
        if not (dt > 0.0 and np.isfinite(dt)):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        output = np.broadcast_to(self.valve_pressure(u), self._pressure.shape).copy()
        self._pending.append((self.time + self.params.valve_delay, output))
        # integrate piecewise: the valve outputs change when a command leaves the delay line
        # (times within 1 ns count as equal: steps of dt add up with rounding errors)
        now, end = self.time, self.time + dt
        while True:
            while self._pending and self._pending[0][0] <= now + 1e-9:
                self._valve_output = self._pending.pop(0)[1]
            until = self._pending[0][0] if self._pending else end
            if until >= end - 1e-9:
                self._integrate(end - now)
                break
            self._integrate(until - now)
            now = until
        self.time = end

    def _integrate(self, dt: float) -> None:
        """Advance the chambers and mechanics by ``dt`` [s] under constant valve outputs."""
        p = self.params
        target = self._valve_output
        n_sub = max(1, int(np.ceil(dt / p.max_substep - 1e-9)))
        h = dt / n_sub
        w = p.extension_natural_frequency
        spring = h * w * w
        damping = 1.0 - h * 2.0 * p.extension_damping * w
        bend_alpha = -np.expm1(-h / p.bend_time_constant)
        pressure, tau, shape = self._pressure, self._tau, self._shape
        for _ in range(n_sub):
            # chamber volume sets the pneumatic time constant: the PEA's grows with its length,
            # a bellows' with its own bend (computed from the previous substep's shape)
            np.multiply(self._extension, p.pea_time_constant / p.pea_rest_length, out=tau[:, 0])
            tau[:, 0] += p.pea_time_constant
            np.multiply(self._bellows, self._tau_bellows_gain, out=tau[:, 1:])
            tau[:, 1:] += p.bellows_time_constant
            pressure += (target - pressure) * -np.expm1(-h / tau)
            self._update_static_shape()
            np.clip(self._shape_play, shape - self._play_width, shape + self._play_width,
                    out=self._shape_play)
            # semi-implicit Euler for the axial mass-spring-damper
            self._extension_rate *= damping
            self._extension_rate += spring * (self._shape_play[:, 0] - self._extension)
            self._extension += h * self._extension_rate
            self._bend += (self._shape_play[:, 1:] - self._bend) * bend_alpha
