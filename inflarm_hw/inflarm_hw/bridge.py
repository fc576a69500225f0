"""The hardware bridge's safety core: commands in, checked and limited outputs to the MCU out.

Pure numpy, no rclpy: the ``hw_bridge`` node stores what arrives on its topics here and writes
what `SafetySupervisor.output` returns through the driver (`inflarm_hw.driver`). Everything the
bridge decides about safety is in this module, so each rule has a test without ROS:

- **Validation** (`check_motor_command`, `check_pressure_command`, `check_config`): non-finite
  values, unknown names, positions outside the joint limits and set pressures outside
  ``[0, chamber_pressure_max]`` (the chamber's rating) reject the command whole with a
  ``ValueError`` naming the problem; feed-forward velocities above the motor limit are
  clamped, and the clamping is reported.
- **Command watchdog** on a steady clock: no fresh motor command within ``cmd_timeout_s`` ->
  motors hold (or zero torque); no fresh pressure command -> chambers to the safe pressure.
- **Limits**: chamber set points within ``[0, chamber_pressure_max]``, link set points within
  ``[link_pressure_min, link_pressure_max]``, pressure slew at most ``pressure_rate``, motor
  position targets slewed at most ``max_velocity``.
- **Latched faults** (until `SafetySupervisor.reset_faults`): a pressure reading over its trip
  level (``over_pressure``), bit-identical for ``frozen_sensor_s`` (``frozen_sensor``) or not
  finite (``sensor_invalid``) -> motors hold, chambers safe, and links vented to
  ``link_fault_pressure`` if a link sensor is the one at fault.
- **Link loss** (``link_lost``, reported by the node): outputs safe until the MCU is back.
- **Wrinkling** (LinkStatus from the load estimator): a link's measured pressure below
  ``(1 + wrinkle_margin)`` times the minimum for its bending moment (eq. (3) of 000_...,
  `inflarm_model.link.min_pressure_for_moment`) -> warning; below the minimum -> motion stopped
  (motors hold) until the pressure or the load is back in the safe range.

Safe outputs take effect at once (no slew limit on the way to safe). The time from detecting a
fault or a timeout to the MCU confirming the safe output (a State whose ``command_seq`` is that
of the first safe command) is measured and reported as ``safe_latency``.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from inflarm_hw.driver import DeviceInfo, McuCommand
from inflarm_hw.mcu_protocol import (
    N_CHAMBERS,
    N_LINKS,
    N_MOTORS,
    Fault,
    FaultCode,
    MotorMode,
    State,
    seq_newer_or_equal,
)
from inflarm_hw.valve import ITV2050, ValveModel, pressure_to_voltage
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import min_pressure_for_moment
from inflarm_model.soft_arm import CHAMBERS, check_chamber_pressures
from inflarm_msgs_json import HardwareStatus, LinkStatus

MOTORS = tuple(FlexibleArm.MOTOR_JOINT_NAMES)
LINKS = ('link_1', 'link_2')
#: Names of the pressure channels in State order: the chambers, then the links.
PRESSURE_CHANNEL_NAMES = tuple(CHAMBERS) + LINKS
#: Faults that hold the safe output until reset.
LATCHED_FAULTS = ('over_pressure', 'frozen_sensor', 'sensor_invalid')
SAFE_MOTOR_OUTPUTS = ('hold', 'zero_torque')
# The longest time step the slew limits integrate over [s] (after a pause, no jump).
_MAX_SLEW_DT = 0.1


@dataclass(frozen=True)
class BridgeConfig:
    """Limits and safe outputs of the bridge (SI units).

    Attributes
    ----------
    cmd_timeout_s : float
        Command watchdog [s], in (0, 2].
    position_min, position_max : tuple of 3 float
        Joint limits of joint_1..joint_3 [rad]; commands outside are rejected.
    max_velocity : float
        Motor slew limit on position targets, and the largest feed-forward [rad/s].
    chamber_pressure_max : float
        Chamber rating: set points outside ``[0, chamber_pressure_max]`` are rejected [Pa].
    chamber_over_pressure : float
        A chamber reading above this is an ``over_pressure`` fault [Pa].
    link_pressure : tuple of 2 float
        Set point of link_1 and link_2 [Pa].
    link_pressure_min, link_pressure_max : float
        Allowed range of the link set points [Pa] (000_...: 10-60 kPa).
    link_over_pressure : float
        A link reading above this is an ``over_pressure`` fault [Pa].
    pressure_rate : float
        Slew limit of every pressure set point [Pa/s].
    safe_motors : str
        ``'hold'`` (brake at the current position) or ``'zero_torque'``.
    safe_chamber_pressure : float
        Chamber set point while safe [Pa] (0: vent).
    link_fault_pressure : float
        Link set point while a link sensor is over pressure, frozen or invalid [Pa] (0: vent).
        Other safe outputs keep the links at their set point (inflated).
    frozen_sensor_s : float
        A pressure reading bit-identical for this long is a ``frozen_sensor`` fault [s];
        0 disables the check (for sensors quantised coarser than their noise).
    wrinkle_margin : float
        Warning band above the wrinkle-safe minimum link pressure, relative [-].
    wrinkle_status_timeout_s : float
        LinkStatus older than this is ignored [s].
    link_radius : float
        Link radius r of eq. (3) [m].
    chamber_valve, link_valve : ValveModel
        The valves behind the chambers and the links (eq. (2)).
    """

    cmd_timeout_s: float = 1.0
    position_min: tuple[float, float, float] = (-math.pi,) * 3
    position_max: tuple[float, float, float] = (math.pi,) * 3
    max_velocity: float = 1.0
    chamber_pressure_max: float = 100e3
    chamber_over_pressure: float = 130e3
    link_pressure: tuple[float, float] = (50e3, 50e3)
    link_pressure_min: float = 10e3
    link_pressure_max: float = 60e3
    link_over_pressure: float = 70e3
    pressure_rate: float = 500e3
    safe_motors: str = 'hold'
    safe_chamber_pressure: float = 0.0
    link_fault_pressure: float = 0.0
    frozen_sensor_s: float = 0.5
    wrinkle_margin: float = 0.2
    wrinkle_status_timeout_s: float = 1.0
    link_radius: float = 0.055
    chamber_valve: ValveModel = ITV2050
    link_valve: ValveModel = ITV2050

    def __post_init__(self) -> None:
        check_config(self)


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(message)


def check_config(c: BridgeConfig) -> None:
    """Raise ``ValueError`` naming the first inconsistent or unsafe value of ``c``."""
    for name, value in vars(c).items():
        if isinstance(value, float):
            _check(math.isfinite(value), f'expected finite {name}, got {value}')
    _check(0.0 < c.cmd_timeout_s <= 2.0,
           f'expected cmd_timeout_s in (0, 2] s (a fail-safe), got {c.cmd_timeout_s}')
    for name, count in (('position_min', 3), ('position_max', 3), ('link_pressure', 2)):
        value = getattr(c, name)
        _check(len(value) == count and all(math.isfinite(v) for v in value),
               f'expected {name} as {count} finite numbers, got {list(value)}')
    _check(all(lo < hi for lo, hi in zip(c.position_min, c.position_max, strict=True)),
           f'expected position_min < position_max per joint, got {list(c.position_min)} and '
           f'{list(c.position_max)}')
    _check(c.max_velocity > 0.0, f'expected max_velocity > 0 rad/s, got {c.max_velocity}')
    _check(0.0 < c.chamber_pressure_max < c.chamber_over_pressure,
           f'expected 0 < chamber_pressure_max < chamber_over_pressure, got '
           f'{c.chamber_pressure_max} and {c.chamber_over_pressure} Pa')
    _check(c.chamber_pressure_max <= c.chamber_valve.full_scale,
           f'expected chamber_pressure_max within the valve range '
           f'({c.chamber_valve.full_scale} Pa), got {c.chamber_pressure_max}')
    _check(0.0 <= c.link_pressure_min < c.link_pressure_max < c.link_over_pressure,
           f'expected 0 <= link_pressure_min < link_pressure_max < link_over_pressure, got '
           f'{c.link_pressure_min}, {c.link_pressure_max} and {c.link_over_pressure} Pa')
    _check(all(c.link_pressure_min <= p <= c.link_pressure_max for p in c.link_pressure),
           f'expected link_pressure within [{c.link_pressure_min}, {c.link_pressure_max}] Pa, '
           f'got {list(c.link_pressure)}')
    _check(c.pressure_rate > 0.0, f'expected pressure_rate > 0 Pa/s, got {c.pressure_rate}')
    _check(c.safe_motors in SAFE_MOTOR_OUTPUTS,
           f'expected safe_motors one of {list(SAFE_MOTOR_OUTPUTS)}, got {c.safe_motors!r}')
    _check(0.0 <= c.safe_chamber_pressure <= c.chamber_pressure_max,
           f'expected safe_chamber_pressure in [0, {c.chamber_pressure_max}] Pa, got '
           f'{c.safe_chamber_pressure}')
    _check(0.0 <= c.link_fault_pressure <= c.link_pressure_max,
           f'expected link_fault_pressure in [0, {c.link_pressure_max}] Pa, got '
           f'{c.link_fault_pressure}')
    _check(c.frozen_sensor_s == 0.0 or 0.05 <= c.frozen_sensor_s <= 10.0,
           f'expected frozen_sensor_s 0 (off) or in [0.05, 10] s, got {c.frozen_sensor_s}')
    _check(0.0 <= c.wrinkle_margin <= 1.0,
           f'expected wrinkle_margin in [0, 1], got {c.wrinkle_margin}')
    _check(0.0 < c.wrinkle_status_timeout_s <= 10.0,
           f'expected wrinkle_status_timeout_s in (0, 10] s, got {c.wrinkle_status_timeout_s}')
    _check(c.link_radius > 0.0, f'expected link_radius > 0 m, got {c.link_radius}')


@dataclass(frozen=True)
class MotorTarget:
    """A checked motor command: targets by joint index, and what was clamped."""

    position: dict[int, float]
    velocity: dict[int, float]
    clamped: tuple[str, ...] = ()


def check_motor_command(names, positions, velocities, config: BridgeConfig) -> MotorTarget:
    """Check a ``motor_position_command`` (JointState fields) against the joint limits.

    Parameters
    ----------
    names : sequence of str
        Some of joint_1..joint_3, each at most once.
    positions : sequence of float, one per name
        Targets [rad], within ``[position_min, position_max]``.
    velocities : sequence of float, empty or one per name
        Feed-forward [rad/s]; clamped to ``max_velocity``.
    config : BridgeConfig

    Returns
    -------
    MotorTarget

    Raises
    ------
    ValueError
        Naming the joint and the problem.
    """
    names, positions, velocities = list(names), list(positions), list(velocities)
    unknown = sorted(set(names) - set(MOTORS))
    _check(not unknown, f'unknown joints {unknown}, expected some of {list(MOTORS)}')
    _check(len(set(names)) == len(names), f'a joint named twice in {names}')
    _check(names, 'no joint named')
    _check(len(positions) == len(names),
           f'{len(positions)} positions for {len(names)} joints {names}')
    _check(not velocities or len(velocities) == len(names),
           f'{len(velocities)} velocities for {len(names)} joints {names} (give none or one '
           'per joint)')
    position, velocity, clamped = {}, {}, []
    for k, name in enumerate(names):
        i = MOTORS.index(name)
        q = float(positions[k])
        _check(math.isfinite(q), f'{name} position {q} is not finite')
        low, high = config.position_min[i], config.position_max[i]
        _check(low <= q <= high,
               f'{name} position {q:.4f} rad outside the joint limits [{low:.4f}, {high:.4f}]')
        position[i] = q
        if velocities:
            v = float(velocities[k])
            _check(math.isfinite(v), f'{name} velocity {v} is not finite')
            if abs(v) > config.max_velocity:
                clamped.append(f'{name} velocity {v:.3f} rad/s clamped to '
                               f'{math.copysign(config.max_velocity, v):.3f}')
                v = math.copysign(config.max_velocity, v)
            velocity[i] = v
    return MotorTarget(position, velocity, tuple(clamped))


@dataclass(frozen=True)
class PressureTarget:
    """A checked pressure command: set points by chamber index [Pa]."""

    pressure: dict[int, float]


def check_pressure_command(pressures: dict, config: BridgeConfig) -> PressureTarget:
    """Check a ``chamber_pressure_command`` (PressureCommand as a dict) against the limits.

    Parameters
    ----------
    pressures : dict of str to float
        Some of PEA, B1..B4 -> set gauge pressure [Pa], within ``[0, chamber_pressure_max]``
        (valves cannot make vacuum; the chamber's rating is not exceeded).
    config : BridgeConfig

    Returns
    -------
    PressureTarget

    Raises
    ------
    ValueError
        Naming the chamber and the problem.
    """
    checked = check_chamber_pressures(pressures, config.chamber_pressure_max)
    return PressureTarget({CHAMBERS.index(name): p for name, p in checked.items()})


@dataclass(frozen=True)
class Event:
    """Something the node should log: ``kind`` groups repeats for throttling."""

    kind: str
    level: str  # 'info', 'warning' or 'error'
    message: str


@dataclass
class _Latched:
    detail: str
    link: bool  # a link channel is at fault: vent the links


@dataclass
class _PendingSafe:
    detected: float
    reason: str
    seq: int | None = None


def _internal(**kwargs):
    """A dataclass field that is internal state: not an __init__ argument, not in repr."""
    return field(init=False, repr=False, **kwargs)


@dataclass
class _Sensor:
    value: float = math.nan
    since: float | None = None


@dataclass
class SafetySupervisor:
    """Commands, sensor states and faults in; the output to write out (see the module doc).

    Parameters
    ----------
    config : BridgeConfig
    device : DeviceInfo
        The MCU's channels (from the handshake).
    """

    config: BridgeConfig
    device: DeviceInfo
    events: list[Event] = field(default_factory=list)
    clamped: int = 0
    rejected: int = 0
    safe_latency: float | None = None
    link_lost: str | None = None
    state: State | None = None
    # internal state, not constructor arguments
    _motor_target: np.ndarray | None = _internal(default=None)
    _motor_velocity: np.ndarray = _internal(default_factory=lambda: np.zeros(N_MOTORS))
    _motor_time: float | None = _internal(default=None)
    _chamber_target: np.ndarray = _internal(default_factory=lambda: np.zeros(N_CHAMBERS))
    _chamber_time: float | None = _internal(default=None)
    _motor_out: np.ndarray | None = _internal(default=None)
    _chamber_out: np.ndarray | None = _internal(default=None)
    _link_out: np.ndarray | None = _internal(default=None)
    _last_output: float | None = _internal(default=None)
    _latched: dict[str, _Latched] = _internal(default_factory=dict)
    _sensors: list[_Sensor] = _internal(default_factory=list)
    _link_status: dict[int, tuple[float, float]] = _internal(default_factory=dict)
    _wrinkle: dict[int, str] = _internal(default_factory=dict)  # link -> 'warn' or 'stop'
    # why each output (motors, valves) is safe, None while it follows; '' before the first
    _reasons: tuple[str | None, str | None] = _internal(default=('', ''))
    _pending: _PendingSafe | None = _internal(default=None)

    def __post_init__(self) -> None:
        self._sensors = [_Sensor() for _ in range(N_CHAMBERS + N_LINKS)]

    @property
    def has_motors(self) -> bool:
        return self.device.n_motors > 0

    @property
    def has_valves(self) -> bool:
        return self.device.n_chambers > 0 or self.device.n_links > 0

    # -- inputs ---------------------------------------------------------------------------------

    def on_motor_command(self, names, positions, velocities, now: float) -> MotorTarget:
        """Store a motor command (unnamed joints keep their target); raises ``ValueError``
        (counted in ``rejected``; the caller reports it)."""
        try:
            _check(self.has_motors, 'this MCU has no motors')
            target = check_motor_command(names, positions, velocities, self.config)
        except ValueError:
            self.rejected += 1
            raise
        if self._motor_target is None:
            self._motor_target = (self._measured_motors() if self._motor_out is None
                                  else self._motor_out.copy())
        self._motor_velocity[:] = 0.0  # feed-forward only for the joints named now
        for i, q in target.position.items():
            self._motor_target[i] = q
            self._motor_velocity[i] = target.velocity.get(i, 0.0)
        self._motor_time = now
        self._report_clamps('motor_command_clamped', 'motor_position_command', target.clamped)
        return target

    def on_pressure_command(self, pressures: dict, now: float) -> PressureTarget:
        """Store a pressure command (unnamed chambers keep theirs); raises ``ValueError``
        (counted in ``rejected``; the caller reports it)."""
        try:
            _check(self.device.n_chambers > 0, 'this MCU has no chamber valves')
            target = check_pressure_command(pressures, self.config)
        except ValueError:
            self.rejected += 1
            raise
        for i, p in target.pressure.items():
            self._chamber_target[i] = p
        self._chamber_time = now
        return target

    def on_link_status(self, status: LinkStatus, now: float) -> None:
        """Store the bending moment of a link (LinkStatus of the load estimator)."""
        if status.link not in LINKS:
            self._event('link_status_rejected', 'warning',
                        f"link_status ignored: unknown link '{status.link}', expected one of "
                        f'{list(LINKS)}')
            return
        self._link_status[LINKS.index(status.link)] = (status.moment, now)

    def set_link_pressure(self, pressure) -> None:
        """New link set points [Pa] (checked as in `check_config`; raises ``ValueError``)."""
        self.config = BridgeConfig(**{**vars(self.config),
                                      'link_pressure': tuple(float(p) for p in pressure)})

    def on_state(self, state: State, now: float) -> None:
        """Check a State report: pressure limits, frozen and invalid sensors, wrinkling; and
        whether it confirms a pending safe output."""
        self.state = state
        readings = list(state.chamber_pressure) + list(state.link_pressure)
        present = [self.device.n_chambers > 0] * N_CHAMBERS + [self.device.n_links > 0] * N_LINKS
        for channel, (value, here) in enumerate(zip(readings, present, strict=True)):
            if here:
                self._check_sensor(channel, value, now)
        if self.has_motors and not all(map(math.isfinite, state.motor_position
                                           + state.motor_velocity + state.motor_torque)):
            self._latch('sensor_invalid', 'a motor reading is not finite', False, now)
        self._check_wrinkling(state, now)
        pending = self._pending
        if pending is not None and pending.seq is not None and seq_newer_or_equal(
                state.command_seq, pending.seq):
            self.safe_latency = now - pending.detected
            self._pending = None
            self._event('safe_confirmed', 'info',
                        f'safe output confirmed by the MCU {self.safe_latency * 1000:.0f} ms '
                        f'after {pending.reason}')

    def on_mcu_fault(self, fault: Fault) -> None:
        """Log a Fault event of the MCU."""
        try:
            code = FaultCode(fault.code).name
        except ValueError:
            code = f'code {fault.code}'
        level = 'warning' if fault.code in (FaultCode.WATCHDOG, FaultCode.PLANT) else 'error'
        self._event(f'mcu_fault_{code}', level,
                    f'MCU fault {code} (channel {fault.channel}, value {fault.value:g})')

    def on_link_lost(self, reason: str, now: float) -> None:
        """The link to the MCU failed (the node reconnects); its watchdog makes it safe."""
        if self.link_lost is None:
            self._event('link_lost', 'error',
                        f'link to the MCU lost: {reason}; its watchdog '
                        f'({self.device.watchdog_s * 1000:.0f} ms) makes the outputs safe; '
                        'reconnecting')
        self.link_lost = reason
        self._motor_out = None  # slew again from what is measured after reconnection

    def on_link_restored(self, device: DeviceInfo, now: float) -> None:
        """The link is back (a new handshake); the MCU must be the same kind."""
        was = self.device
        if (device.n_motors, device.n_chambers, device.n_links) != (
                was.n_motors, was.n_chambers, was.n_links):
            raise ValueError(
                f'the MCU came back with other channels ({device.n_motors} motors, '
                f'{device.n_chambers} chambers, {device.n_links} links; configured with '
                f'{was.n_motors}, {was.n_chambers}, {was.n_links})')
        self.device = device
        self._pending = None  # sequence numbers of the old session mean nothing now
        if self.link_lost is not None:
            self._event('link_restored', 'info',
                        'link to the MCU restored; outputs follow fresh commands again')
        self.link_lost = None

    def reset_faults(self, now: float) -> tuple[bool, str]:
        """Clear the latched faults, if their cause is gone; ``(success, message)``."""
        if not self._latched:
            return True, 'no latched fault'
        state = self.state
        if 'over_pressure' in self._latched and state is not None:
            over = self._over_pressure(list(state.chamber_pressure) + list(state.link_pressure))
            if over:
                return False, f'over_pressure persists: {over}'
        names = sorted(self._latched)
        self._latched.clear()
        for sensor in self._sensors:
            sensor.since = None
            sensor.value = math.nan
        self._event('faults_reset', 'info', f'latched faults reset: {", ".join(names)}')
        return True, f'reset {", ".join(names)}'

    # -- output ---------------------------------------------------------------------------------

    def output(self, now: float, enabled: bool) -> McuCommand:
        """What to write now. ``enabled``: the lifecycle state is active."""
        c = self.config
        dt = min(now - self._last_output, _MAX_SLEW_DT) if self._last_output is not None \
            else 0.0
        self._last_output = now
        motor_reason, valve_reason = self._safe_reasons(now, enabled)
        self._note_transition(motor_reason, valve_reason, now)
        link_fault = any(f.link for f in self._latched.values())

        command = {}
        if self.has_motors:
            measured = self._measured_motors()
            if motor_reason is None:
                previous = measured if self._motor_out is None else self._motor_out
                step = np.clip(self._motor_target - previous, -c.max_velocity * dt,
                               c.max_velocity * dt)
                self._motor_out = previous + step
                limited = np.abs(self._motor_target - previous) > c.max_velocity * dt
                velocity = np.where(limited, step / dt if dt > 0.0 else 0.0,
                                    self._motor_velocity)
                command.update(motor_mode=MotorMode.POSITION,
                               motor_position=self._motor_out.copy(), motor_velocity=velocity)
            else:
                # the next command starts from where the motors are
                self._motor_out = self._motor_target = None
                mode = MotorMode.HOLD if (c.safe_motors == 'hold'
                                          or motor_reason.startswith('wrinkle')) \
                    else MotorMode.OFF
                command.update(motor_mode=mode, motor_position=measured)
        if self.has_valves:
            safe_chambers = np.full(N_CHAMBERS, c.safe_chamber_pressure)
            if valve_reason is None:
                self._chamber_out = self._slew(self._chamber_out, self._chamber_target, dt,
                                               safe_chambers)
            else:
                self._chamber_out = safe_chambers
            links = np.asarray(c.link_pressure, dtype=float)
            if link_fault:
                self._link_out = np.full(N_LINKS, c.link_fault_pressure)
            else:
                self._link_out = self._slew(self._link_out, links, dt, links)
            command.update(
                chamber_voltage=pressure_to_voltage(self._chamber_out, c.chamber_valve),
                link_voltage=pressure_to_voltage(self._link_out, c.link_valve))
        return McuCommand(**command)

    def sent(self, seq: int) -> None:
        """The node wrote the last `output` as frames up to ``seq``."""
        if self._pending is not None and self._pending.seq is None:
            self._pending.seq = seq

    def status(self, state: str, link: str, bad_frames: int = 0) -> HardwareStatus:
        """A HardwareStatus for the node's lifecycle ``state`` and ``link`` labels."""
        motor_reason, valve_reason = (r if r != '' else 'starting' for r in self._reasons)
        if not self.has_motors:
            motors = 'none'
        elif motor_reason is None:
            motors = 'follow'
        else:
            motors = 'hold' if (self.config.safe_motors == 'hold'
                                or motor_reason.startswith('wrinkle')) else 'zero_torque'
        valves = 'none' if not self.has_valves else 'follow' if valve_reason is None else 'safe'
        faults = sorted(self.faults)
        reasons = [r for r in dict.fromkeys((motor_reason, valve_reason)) if r]
        return HardwareStatus(
            state=state, link=link, motors=motors, valves=valves, faults=tuple(faults),
            latched=tuple(sorted(self._latched)), reason='; '.join(reasons),
            safe_latency=self.safe_latency, clamped=self.clamped, rejected=self.rejected,
            bad_frames=bad_frames)

    @property
    def faults(self) -> dict[str, str]:
        """Active faults -> detail (latched ones, link loss, wrinkling)."""
        faults = {name: f.detail for name, f in self._latched.items()}
        if self.link_lost is not None:
            faults['link_lost'] = self.link_lost
        for link, level in self._wrinkle.items():
            name = 'wrinkle_stop' if level == 'stop' else 'wrinkle_risk'
            faults[name] = f'{faults[name]}, {LINKS[link]}' if name in faults else LINKS[link]
        return faults

    def drain_events(self) -> list[Event]:
        """The events since the last call, oldest first."""
        events, self.events = self.events, []
        return events

    # -- internals ------------------------------------------------------------------------------

    def _event(self, kind: str, level: str, message: str) -> None:
        self.events.append(Event(kind, level, message))

    def _report_clamps(self, kind: str, topic: str, clamped: tuple[str, ...]) -> None:
        if clamped:
            self.clamped += 1
            self._event(kind, 'warning', f'{topic} clamped: {"; ".join(clamped)}')

    def _measured_motors(self) -> np.ndarray:
        if self.state is None:
            return np.zeros(N_MOTORS)
        return np.array(self.state.motor_position, dtype=float)

    def _slew(self, previous: np.ndarray | None, target: np.ndarray, dt: float,
              start: np.ndarray) -> np.ndarray:
        previous = start if previous is None else previous
        step = self.config.pressure_rate * dt
        return previous + np.clip(target - previous, -step, step)

    def _safe_reasons(self, now: float, enabled: bool) -> tuple[str | None, str | None]:
        c = self.config
        common = None
        if not enabled:
            common = 'inactive'
        elif self.link_lost is not None:
            common = 'link_lost'
        elif self._latched:
            common = ', '.join(f'{name} ({f.detail})' for name, f in sorted(self._latched.items()))
        motor = valve = common
        if motor is None:
            if self._motor_time is None:
                motor = 'no motor_position_command yet'
            elif now - self._motor_time > c.cmd_timeout_s:
                motor = f'no motor_position_command for {c.cmd_timeout_s} s'
            elif any(level == 'stop' for level in self._wrinkle.values()):
                # before the fresh-command wait: held cycles drop the target, and the stop
                # must keep holding (not zero torque) and keep naming itself
                motor = 'wrinkle_stop: a link is below its wrinkle-safe pressure'
            elif self._motor_target is None:  # after a safe output: a fresh command resumes
                motor = 'waiting for a fresh motor_position_command'
        if valve is None and self.device.n_chambers > 0:
            if self._chamber_time is None:
                valve = 'no chamber_pressure_command yet'
            elif now - self._chamber_time > c.cmd_timeout_s:
                valve = f'no chamber_pressure_command for {c.cmd_timeout_s} s'
        return (motor if self.has_motors else None), (valve if self.has_valves else None)

    def _deadline(self, reason: str, now: float) -> float:
        """When the condition behind ``reason`` arose (a timeout: when it expired)."""
        c = self.config
        if reason.startswith('no motor_position_command for') and self._motor_time is not None:
            return min(now, self._motor_time + c.cmd_timeout_s)
        if reason.startswith('no chamber_pressure_command for') \
                and self._chamber_time is not None:
            return min(now, self._chamber_time + c.cmd_timeout_s)
        return now

    def _note_transition(self, motor: str | None, valve: str | None, now: float) -> None:
        before_motor, before_valve = self._reasons
        self._reasons = (motor, valve)
        for group, before, after in (('motor', before_motor, motor),
                                     ('valve', before_valve, valve)):
            if before is None and after is not None:
                # no confirmation can come over a lost link (the MCU's watchdog acts)
                if self._pending is None and after != 'link_lost':
                    self._pending = _PendingSafe(self._deadline(after, now), after)
                self._event(f'safe_{group}', 'warning', f'safe {group} output: {after}')
            elif before and after is None:
                self._event(f'follow_{group}', 'info', f'{group} outputs follow the commands')

    def _latch(self, name: str, detail: str, link: bool, now: float) -> None:
        if name in self._latched:
            return
        self._latched[name] = _Latched(detail, link)
        self._event(name, 'error', f'{name}: {detail}; venting, latched until ~/reset_fault')

    def _over_pressure(self, readings: list[float]) -> str:
        c = self.config
        over = []
        for channel, value in enumerate(readings):
            is_link = channel >= N_CHAMBERS
            present = self.device.n_links > 0 if is_link else self.device.n_chambers > 0
            limit = c.link_over_pressure if is_link else c.chamber_over_pressure
            if present and math.isfinite(value) and value > limit:
                over.append(f'{PRESSURE_CHANNEL_NAMES[channel]} at {value:.0f} Pa > '
                            f'{limit:.0f} Pa')
        return ', '.join(over)

    def _check_sensor(self, channel: int, value: float, now: float) -> None:
        name = PRESSURE_CHANNEL_NAMES[channel]
        is_link = channel >= N_CHAMBERS
        if not math.isfinite(value):
            self._latch('sensor_invalid', f'{name} reads {value}', is_link, now)
            return
        limit = self.config.link_over_pressure if is_link else self.config.chamber_over_pressure
        if value > limit:
            self._latch('over_pressure', f'{name} at {value:.0f} Pa > {limit:.0f} Pa', is_link,
                        now)
        sensor = self._sensors[channel]
        frozen_s = self.config.frozen_sensor_s
        if value != sensor.value:
            sensor.value, sensor.since = value, now
        elif frozen_s > 0.0 and sensor.since is not None and now - sensor.since >= frozen_s:
            self._latch('frozen_sensor',
                        f'{name} has read {value:.1f} Pa for {now - sensor.since:.2f} s',
                        is_link, now)

    def _check_wrinkling(self, state: State, now: float) -> None:
        if not self.device.n_links:
            return
        c = self.config
        before = dict(self._wrinkle)
        self._wrinkle.clear()
        for link, (moment, received) in self._link_status.items():
            if now - received > c.wrinkle_status_timeout_s:
                continue
            pressure = state.link_pressure[link]
            p_min = float(min_pressure_for_moment(moment, c.link_radius))
            if pressure < p_min:
                self._wrinkle[link] = 'stop'
            elif pressure < (1.0 + c.wrinkle_margin) * p_min:
                self._wrinkle[link] = 'warn'
            level = self._wrinkle.get(link)
            if level is not None and before.get(link) != level:
                what = 'motion stopped' if level == 'stop' else 'warning'
                self._event(f'wrinkle_{level}', 'error' if level == 'stop' else 'warning',
                            f'{LINKS[link]} at {pressure:.0f} Pa, wrinkle-safe minimum '
                            f'{p_min:.0f} Pa for its {moment:.2f} N m bending moment '
                            f'(eq. 3): {what}')
        for link in before:
            if link not in self._wrinkle:
                self._event('wrinkle_clear', 'info', f'{LINKS[link]} back above the '
                            'wrinkle-safe pressure band')

