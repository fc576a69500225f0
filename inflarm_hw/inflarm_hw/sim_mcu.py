"""A simulated microcontroller: the MCU link protocol in front of the simulated plants.

The core of the ``sim_mcu`` executable (pure numpy, no rclpy, no I/O): bytes from the serial line
go in through `SimMcu.receive`, time goes on through `SimMcu.step`, and both return the bytes
the MCU sends back. It behaves as the firmware specified in ``inflarm_hw/README.md``: a session
opened by HELLO, commands applied as they arrive, a command watchdog (no valid command for
``watchdog_ms``: motors hold, chamber valves vent, link valves keep their set point so the links
stay inflated), a State report per step, Fault events. Behind it are the plant cores: the
inflatable arm's three position-controlled motors and two link valves
(`inflarm_hw.inflatable_arm_sim`) and the soft arm's five chamber valves
(`inflarm_hw.sra_plant`); either or both.

Valves get control voltages, as from an MCU's DACs; eq. (2) turns them into pressures
(`inflarm_hw.valve`). Pressure sensors add Gaussian noise (a real sensor is never bit-identical
twice, which the bridge's frozen-sensor check relies on). Motor torques are reported as the
torque each motor applies to its joint (the ros2_control convention), the negative of the load
torque ``tau_m`` of eq. (6) of 000_... that `InflatableArmSim` computes.

Fault injection (`SimMcu.inject`, or FAULT_INJECT frames): drop bytes, corrupt CRCs, go silent,
stick a pressure sensor, over-pressure a valve.

`McuPort` is the MCU's end of the serial line: a new pseudo-terminal (the bridge opens the path
it prints, or a symlink to it) or an existing tty device.
"""

import contextlib
from dataclasses import dataclass
import errno
import math
import os
import tty

import numpy as np
import numpy.typing as npt

from inflarm_hw.inflatable_arm_sim import ArmSimState, InflatableArmSim
from inflarm_hw.mcu_protocol import (
    N_CHAMBERS,
    N_LINKS,
    N_MOTORS,
    PRESSURE_CHANNELS,
    PROTOCOL_VERSION,
    Fault,
    FaultCode,
    FaultInject,
    FaultKind,
    FrameDecoder,
    Heartbeat,
    HeartbeatAck,
    Hello,
    HelloAck,
    Message,
    MotorCommand,
    MotorMode,
    State,
    StatusFlag,
    ValveCommand,
    encode_frame,
    finite,
)
from inflarm_hw.sra_plant import SoftArmPlant
from inflarm_hw.valve import ITV2050, ValveModel, pressure_to_voltage, voltage_to_pressure

# Lowest link pressure handed to the arm's wrinkling model (it needs a positive one) [Pa].
_MIN_MODEL_LINK_PRESSURE = 100.0
#: Fault events of these codes come with frames or steps, so they are rate-limited: one per
#: (code, channel) within `FAULT_REPEAT_S`. The others are one-off events (a watchdog trip, an
#: answer to a HELLO or a FAULT_INJECT) and are always sent.
RATE_LIMITED_FAULTS = frozenset({FaultCode.COMMAND_INVALID, FaultCode.MODE_UNSUPPORTED,
                                 FaultCode.NO_SESSION, FaultCode.PLANT})
#: A rate-limited fault event of one (code, channel) is sent at most this often [s].
FAULT_REPEAT_S = 1.0


@dataclass(frozen=True)
class SimMcuParams:
    """Constants of the simulated MCU.

    Attributes
    ----------
    firmware_version : int
        Reported in HELLO_ACK.
    protocol_version : int
        The protocol version it speaks (another value simulates an incompatible firmware).
    default_watchdog_s, min_watchdog_s, max_watchdog_s : float
        Command watchdog when HELLO asks for 0, and the range a request is clamped to [s].
    pressure_noise_pa : float
        Standard deviation of every pressure reading [Pa].
    link_time_constant_s : float
        First-order time constant of a link's pressure behind its valve's output [s].
    link_valve : ValveModel
        The links' inflation valves (eq. (2)).
    allow_injection : bool
        Accept FAULT_INJECT frames (real firmware answers INJECTION_UNSUPPORTED).
    """

    firmware_version: int = 1
    protocol_version: int = PROTOCOL_VERSION
    default_watchdog_s: float = 0.25
    min_watchdog_s: float = 0.02
    max_watchdog_s: float = 2.0
    pressure_noise_pa: float = 20.0
    link_time_constant_s: float = 1.0
    link_valve: ValveModel = ITV2050
    allow_injection: bool = True

    def __post_init__(self) -> None:
        if not 0.0 < self.min_watchdog_s <= self.default_watchdog_s <= self.max_watchdog_s:
            raise ValueError('expected 0 < min_watchdog_s <= default_watchdog_s <= '
                             f'max_watchdog_s, got {self.min_watchdog_s}, '
                             f'{self.default_watchdog_s}, {self.max_watchdog_s} s')
        if not (math.isfinite(self.pressure_noise_pa) and self.pressure_noise_pa >= 0.0):
            raise ValueError(f'expected pressure_noise_pa >= 0, got {self.pressure_noise_pa}')
        if not (math.isfinite(self.link_time_constant_s) and self.link_time_constant_s > 0.0):
            raise ValueError(
                f'expected link_time_constant_s > 0, got {self.link_time_constant_s}')


@dataclass(frozen=True)
class Injection:
    """An injected fault: its kind, channel, value and end time (inf: until cleared)."""

    kind: FaultKind
    channel: int
    value: float
    until: float


class SimMcu:
    """The simulated MCU in front of the simulated inflatable arm, soft arm, or both.

    Parameters
    ----------
    arm : InflatableArmSim, optional
        The inflatable arm (three motors, two link valves and pressure sensors).
    sra : SoftArmPlant, optional
        The soft arm, ``n = 1`` (five chamber valves and pressure sensors).
    link_pressure : array-like, shape (2,)
        Initial pressure of link_1 and link_2, also their valves' initial set point [Pa]
        (the arm starts deployed). Ignored without ``arm``.
    params : SimMcuParams
    rng : numpy.random.Generator, optional
        Source of the sensor noise and of the injected byte drops and CRC corruptions.
    """

    def __init__(self, arm: InflatableArmSim | None = None, sra: SoftArmPlant | None = None,
                 link_pressure: npt.ArrayLike = (50e3, 50e3),
                 params: SimMcuParams = SimMcuParams(),  # noqa: B008 (frozen)
                 rng: np.random.Generator | None = None) -> None:
        if arm is None and sra is None:
            raise ValueError('expected arm, sra or both, got neither')
        if sra is not None and sra.n != 1:
            raise ValueError(f'expected sra with n = 1, got n = {sra.n}')
        pressure = np.asarray(link_pressure, dtype=float)
        if pressure.shape != (N_LINKS,) or not (np.isfinite(pressure).all()
                                               and (pressure >= 0.0).all()):
            raise ValueError(f'expected link_pressure as 2 finite pressures >= 0 Pa, got '
                             f'{pressure.tolist()}')
        self.arm, self.sra, self.params = arm, sra, params
        self.rng = rng if rng is not None else np.random.default_rng()
        self.n_motors = N_MOTORS if arm is not None else 0
        self.n_chambers = N_CHAMBERS if sra is not None else 0
        self.n_links = N_LINKS if arm is not None else 0
        self.link_pressure = pressure.copy()
        self.link_voltage = pressure_to_voltage(pressure, params.link_valve)
        self.chamber_voltage = np.zeros(N_CHAMBERS)
        self.motor_mode = MotorMode.HOLD
        self.decoder = FrameDecoder()
        self.session = False
        self.watchdog_s = params.default_watchdog_s
        self.last_command_time: float | None = None
        self.watchdog_tripped = True  # outputs safe until the first command of a session
        self.command_seq = 0
        self.arm_state: ArmSimState | None = arm.state() if arm is not None else None
        self.injections: list[Injection] = []
        self._stuck: dict[int, float] = {}
        self._tx_seq = 0
        self._rx_base = (0, 0)
        self._fault_sent: dict[tuple[int, int], float] = {}
        self._hold()

    # -- bytes in, bytes out ---------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> bytes:
        """Take bytes from the serial line at time ``now`` [s]; return the reply bytes."""
        self._expire(now)
        # frame by frame: the replies to a HELLO are numbered from 0
        return b''.join(self._transmit(self._handle(frame.seq, frame.message, now))
                        for frame in self.decoder.feed(data))

    def step(self, dt: float, now: float) -> bytes:
        """Advance the plants ``dt`` seconds to ``now``; return the State report (and any
        fault event) bytes."""
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        self._expire(now)
        out: list[Message] = []
        if (self.session and not self.watchdog_tripped and self.last_command_time is not None
                and now - self.last_command_time > self.watchdog_s):
            self.watchdog_tripped = True
            self._safe()
            out.append(Fault(FaultCode.WATCHDOG, 0, float(now - self.last_command_time)))
        out += self._advance(dt, now)
        if self.session:
            out.append(self._state(now))
        return self._transmit(out)

    def inject(self, kind: int, channel: int, value: float, duration_s: float,
               now: float) -> None:
        """Fake a fault from ``now`` for ``duration_s`` [s] (0: until a CLEAR).

        Parameters
        ----------
        kind : FaultKind
            CLEAR ends every injection.
        channel : int
            Pressure channel (0-4 chambers PEA, B1..B4; 5-6 links) for STICK_SENSOR and
            OVER_PRESSURE.
        value : float
            Share of bytes or frames (0-1) for DROP_BYTES and CORRUPT_CRC, pressure [Pa] for
            OVER_PRESSURE.
        duration_s : float
            >= 0 [s].

        Raises
        ------
        ValueError
            If the kind is unknown or a value is out of its range.
        """
        kind = _fault_kind(kind)
        if not (math.isfinite(duration_s) and duration_s >= 0.0):
            raise ValueError(f'expected duration_s >= 0, got {duration_s}')
        if kind == FaultKind.CLEAR:
            self.injections.clear()
            self._stuck.clear()
            return
        if kind in (FaultKind.DROP_BYTES, FaultKind.CORRUPT_CRC) and not 0.0 <= value <= 1.0:
            raise ValueError(f'expected a share in [0, 1] for {kind.name}, got {value}')
        if kind in (FaultKind.STICK_SENSOR, FaultKind.OVER_PRESSURE):
            if not self._has_pressure_channel(channel):
                raise ValueError(f'expected a pressure channel this MCU has for {kind.name}, '
                                 f'got {channel}')
            if kind == FaultKind.OVER_PRESSURE and not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'expected a pressure >= 0 Pa for OVER_PRESSURE, got {value}')
        until = now + duration_s if duration_s > 0.0 else math.inf
        self.injections = [i for i in self.injections
                           if (i.kind, i.channel) != (kind, channel)]
        self.injections.append(Injection(kind, channel, float(value), until))
        if kind == FaultKind.STICK_SENSOR:
            self._stuck[channel] = float(self._pressures()[channel])

    # -- outputs --------------------------------------------------------------------------------

    def _hold(self) -> None:
        if self.arm is not None:
            self.arm.command(self.arm.q_m)

    def _safe(self) -> None:
        """The watchdog's safe output: motors hold, chambers vent, links keep their set point."""
        self.motor_mode = MotorMode.HOLD
        self._hold()
        self.chamber_voltage[:] = 0.0

    def _handle(self, seq: int, message: Message, now: float) -> list[Message]:
        if isinstance(message, Hello):
            return self._hello(seq, message)
        if isinstance(message, Heartbeat):
            return [HeartbeatAck(message.time_ms)]
        if isinstance(message, FaultInject):
            unsupported = [Fault(FaultCode.INJECTION_UNSUPPORTED, message.channel,
                                 float(message.kind))]
            if not self.params.allow_injection:
                return unsupported
            try:
                self.inject(message.kind, message.channel, message.value, message.duration_s,
                            now)
            except ValueError:
                return unsupported
            return []
        if not isinstance(message, (MotorCommand, ValveCommand)):
            return []  # MCU -> host types: not for the MCU
        if not self.session:
            return self._fault_once(FaultCode.NO_SESSION, int(message.TYPE), 0.0, now)
        replies = self._motor(message, now) if isinstance(message, MotorCommand) \
            else self._valves(message)
        if replies is None:
            return self._fault_once(FaultCode.COMMAND_INVALID, int(message.TYPE), 0.0,
                                    now)
        self.command_seq = seq
        self.last_command_time = now
        self.watchdog_tripped = False
        return replies

    def _hello(self, seq: int, hello: Hello) -> list[Message]:
        """Every HELLO ends the session there is (outputs safe) and restarts the MCU's
        numbering: the reply is frame 0. One of this version opens a new session."""
        p = self.params
        self._tx_seq = 0
        self.last_command_time = None
        self.watchdog_tripped = True
        self._safe()
        if hello.protocol_version != p.protocol_version:
            self.session = False
            return [HelloAck(p.protocol_version, p.firmware_version, 0, self.n_motors,
                             self.n_chambers, self.n_links),
                    Fault(FaultCode.VERSION_MISMATCH, 0, float(hello.protocol_version))]
        requested = hello.watchdog_ms / 1000.0
        self.watchdog_s = (p.default_watchdog_s if requested == 0.0
                           else min(max(requested, p.min_watchdog_s), p.max_watchdog_s))
        self.session = True
        # the decoder restarts its gap count at a HELLO; the counters restart here
        self._rx_base = (self.decoder.stats.bad_frames, self.decoder.stats.lost)
        self.command_seq = seq  # until a command is applied: not newer than any of them
        return [HelloAck(p.protocol_version, p.firmware_version, round(self.watchdog_s * 1000),
                         self.n_motors, self.n_chambers, self.n_links)]

    def _motor(self, command: MotorCommand, now: float) -> list[Message] | None:
        if self.arm is None:
            return []
        if command.mode == MotorMode.POSITION:
            if not (finite(command.position) and finite(command.velocity)):
                return None
            self.arm.command(command.position, command.velocity)
            self.motor_mode = MotorMode.POSITION
            return []
        if command.mode in (MotorMode.HOLD, MotorMode.OFF):
            # the simulated arm has no dynamics: zero torque is simulated as a hold
            if self.motor_mode != command.mode:
                self._hold()  # where the motors are when the hold begins
            self.motor_mode = MotorMode(command.mode)
            return []
        if command.mode == MotorMode.TORQUE:
            if self.motor_mode != MotorMode.HOLD:
                self._hold()
            self.motor_mode = MotorMode.HOLD
            return self._fault_once(FaultCode.MODE_UNSUPPORTED, 0, float(command.mode), now)
        return None

    def _valves(self, command: ValveCommand) -> list[Message] | None:
        if not (finite(command.chamber_voltage) and finite(command.link_voltage)):
            return None
        self.chamber_voltage[:] = command.chamber_voltage
        self.link_voltage[:] = command.link_voltage
        return []

    # -- plants and sensors ---------------------------------------------------------------------

    def _active(self, kind: FaultKind) -> list[Injection]:
        return [i for i in self.injections if i.kind == kind]

    def _expire(self, now: float) -> None:
        kept = [i for i in self.injections if i.until > now]
        if len(kept) != len(self.injections):
            self.injections = kept
            sticks = {i.channel for i in self._active(FaultKind.STICK_SENSOR)}
            self._stuck = {c: v for c, v in self._stuck.items() if c in sticks}

    def _advance(self, dt: float, now: float) -> list[Message]:
        over = {i.channel: i.value for i in self._active(FaultKind.OVER_PRESSURE)}
        out: list[Message] = []
        if self.sra is not None:
            voltage = self.chamber_voltage.copy()
            for channel, pressure in over.items():
                if channel < N_CHAMBERS:
                    voltage[channel] = pressure_to_voltage(pressure, self.sra.params.valve)
            self.sra.step_valve_voltages(voltage, dt)
        if self.arm is not None:
            target = voltage_to_pressure(self.link_voltage, self.params.link_valve)
            for channel, pressure in over.items():
                if channel >= N_CHAMBERS:
                    target[channel - N_CHAMBERS] = pressure
            alpha = -math.expm1(-dt / self.params.link_time_constant_s)
            self.link_pressure += (target - self.link_pressure) * alpha
            if self.arm.params.wrinkling:
                self.arm.set_link_pressure(np.maximum(self.link_pressure,
                                                      _MIN_MODEL_LINK_PRESSURE))
            try:
                self.arm_state = self.arm.step(dt)
            except RuntimeError:
                out += self._fault_once(FaultCode.PLANT, 0, 0.0, now)
        return out

    def _pressures(self) -> npt.NDArray[np.float64]:
        """True pressures of every pressure channel (zeros where absent) [Pa]."""
        pressures = np.zeros(PRESSURE_CHANNELS)
        if self.sra is not None:
            pressures[:N_CHAMBERS] = self.sra.chamber_pressures[0]
        if self.arm is not None:
            pressures[N_CHAMBERS:] = self.link_pressure
        return pressures

    def _has_pressure_channel(self, channel: int) -> bool:
        return (0 <= channel < N_CHAMBERS and self.sra is not None) or (
            N_CHAMBERS <= channel < PRESSURE_CHANNELS and self.arm is not None)

    def _state(self, now: float) -> State:
        readings = self._pressures()
        if self.params.pressure_noise_pa > 0.0:
            readings += self.rng.normal(0.0, self.params.pressure_noise_pa, PRESSURE_CHANNELS)
        present = [self._has_pressure_channel(c) for c in range(PRESSURE_CHANNELS)]
        readings = np.where(present, readings, 0.0)
        for channel, value in self._stuck.items():
            readings[channel] = value
        status = StatusFlag.SESSION if self.session else StatusFlag(0)
        if self.watchdog_tripped:
            status |= StatusFlag.WATCHDOG
        elif self.motor_mode == MotorMode.POSITION and self.arm is not None:
            status |= StatusFlag.MOTORS_ACTIVE
        if self.injections:
            status |= StatusFlag.FAULT_INJECTED
        motors = self.arm_state
        bad, lost = self.decoder.stats.bad_frames, self.decoder.stats.lost
        return State(
            time_ms=int(now * 1000.0) & 0xFFFFFFFF, status=int(status),
            command_seq=self.command_seq, rx_errors=(bad - self._rx_base[0]) & 0xFFFF,
            rx_lost=(lost - self._rx_base[1]) & 0xFFFF,
            motor_position=motors.q_m if motors is not None else (0.0,) * N_MOTORS,
            motor_velocity=motors.dq_m if motors is not None else (0.0,) * N_MOTORS,
            motor_torque=-motors.tau_m if motors is not None else (0.0,) * N_MOTORS,
            chamber_pressure=readings[:N_CHAMBERS], link_pressure=readings[N_CHAMBERS:])

    # -- transmission and its faults ------------------------------------------------------------

    def _fault_once(self, code: FaultCode, channel: int, value: float,
                    now: float) -> list[Message]:
        """A rate-limited fault event: none if one of this (code, channel) went out within
        `FAULT_REPEAT_S`."""
        last = self._fault_sent.get((code, channel))
        if last is not None and now - last < FAULT_REPEAT_S:
            return []
        self._fault_sent[(code, channel)] = now
        return [Fault(code, channel, value)]

    def _transmit(self, messages: list[Message]) -> bytes:
        if not messages or self._active(FaultKind.SILENT):
            self._tx_seq += len(messages)
            return b''
        corrupt = max((i.value for i in self._active(FaultKind.CORRUPT_CRC)), default=0.0)
        frames = []
        for message in messages:
            bad = corrupt > 0.0 and self.rng.random() < corrupt
            frames.append(encode_frame(message, self._tx_seq, crc_xor=0x5A5A5A5A if bad else 0))
            self._tx_seq += 1
        data = b''.join(frames)
        drop = max((i.value for i in self._active(FaultKind.DROP_BYTES)), default=0.0)
        if drop > 0.0:
            keep = self.rng.random(len(data)) >= drop
            data = bytes(np.frombuffer(data, dtype=np.uint8)[keep])
        return data


def _fault_kind(kind: int) -> FaultKind:
    try:
        return FaultKind(kind)
    except ValueError:
        raise ValueError(f'expected a FaultKind, got {kind!r}') from None


class McuPort:
    """The MCU's end of a serial line: a new pseudo-terminal, or an existing tty.

    Parameters
    ----------
    device : str
        ``''``: open a new pty (`os.openpty`), whose other end, `path`, the bridge opens.
        Otherwise a tty device to use as the MCU's UART (e.g. one end of a socat pty pair).
    link : str
        With a new pty: also make this symlink to `path` (replaced if it exists, removed on
        `close`), so the bridge can be configured with a fixed path.

    Reads and writes never block: bytes the line cannot take are dropped (counted in
    `tx_dropped`), as a UART with nobody listening drops them.
    """

    def __init__(self, device: str = '', link: str = '') -> None:
        self.link = ''
        self.tx_dropped = 0
        self._peer = None
        if device:
            if link:
                raise ValueError('expected link only with a new pty (device empty)')
            try:
                self._fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            except OSError as err:
                raise ValueError(f'device {device!r} cannot be opened: {err}') from None
            tty.setraw(self._fd)
            self.path = device
        else:
            self._fd, self._peer = os.openpty()
            # raw on both sides: no echo, no line editing, every byte as it is (0x00 included);
            # holding the peer open keeps the line up while no bridge has it open
            tty.setraw(self._peer)
            tty.setraw(self._fd)
            os.set_blocking(self._fd, False)
            self.path = os.ttyname(self._peer)
            if link:
                temporary = f'{link}.{os.getpid()}.tmp'
                try:
                    os.symlink(self.path, temporary)
                    os.replace(temporary, link)
                except OSError as err:
                    self.close()
                    raise ValueError(f'link {link!r} cannot be made: {err}') from None
                self.link = link

    def read(self) -> bytes:
        """Every byte waiting on the line (b'' if none)."""
        chunks = []
        while True:
            try:
                chunk = os.read(self._fd, 4096)
            except BlockingIOError:
                break
            except OSError as err:
                if err.errno == errno.EIO:  # the other end is closed: nothing to read
                    break
                raise
            if not chunk:
                break
            chunks.append(chunk)
        return b''.join(chunks)

    def write(self, data: bytes) -> None:
        """Send ``data``; what the line cannot take now is dropped."""
        while data:
            try:
                written = os.write(self._fd, data)
            except (BlockingIOError, OSError):
                self.tx_dropped += 1
                return
            data = data[written:]

    def close(self) -> None:
        """Close the line; remove the symlink if it still points at this pty."""
        if self.link:
            with contextlib.suppress(OSError):
                if os.readlink(self.link) == self.path:
                    os.remove(self.link)
            self.link = ''
        for fd in (self._fd, self._peer):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._fd = self._peer = None
