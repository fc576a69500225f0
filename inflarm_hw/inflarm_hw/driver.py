"""The hardware interface to the MCU over a serial port: ``read()`` and ``write()``, no rclpy.

As a ros2_control hardware component: `McuDriver.read` takes what the MCU reported since the
last call, `McuDriver.write` sends the commands. Opening the port runs the version handshake
(HELLO / HELLO_ACK of `inflarm_hw.mcu_protocol`); the link counts as lost when the port fails
or no valid frame arrives within ``link_timeout_s``, and `McuDriver.connect` opens it again.
Every failure is a `McuError` whose message says what happened; the driver is then closed.

The serial port is pyserial's, opened non-blocking and exclusively (a second bridge on the same
port fails to open it), so ``read()`` and ``write()`` never wait.
"""

from collections.abc import Callable
import contextlib
from dataclasses import dataclass, field
import enum
import math
import time

import numpy as np
import numpy.typing as npt
import serial

from inflarm_hw.mcu_protocol import (
    N_CHAMBERS,
    N_LINKS,
    N_MOTORS,
    PROTOCOL_VERSION,
    DecoderStats,
    Fault,
    FaultInject,
    FrameDecoder,
    Heartbeat,
    HeartbeatAck,
    Hello,
    HelloAck,
    Message,
    MotorCommand,
    MotorMode,
    State,
    ValveCommand,
    encode_frame,
)

#: How often the bridge sends a HEARTBEAT to measure the round trip [s] (10 Hz).
HEARTBEAT_PERIOD_S = 0.1


class McuError(Exception):
    """The MCU cannot be reached or spoken to; the message says why."""


class LinkError(McuError):
    """The serial link failed: the port, the handshake, or silence."""


class VersionError(McuError):
    """The MCU speaks another protocol version."""


@dataclass(frozen=True)
class DriverConfig:
    """How to reach the MCU.

    Attributes
    ----------
    port : str
        Serial device, e.g. ``/dev/ttyACM0`` or the pty path `sim_mcu` prints.
    baudrate : int
        Line speed [bit/s] (a pty ignores it).
    handshake_timeout_s : float
        Longest wait for HELLO_ACK after opening [s].
    link_timeout_s : float
        The link counts as lost after this long without a valid frame [s].
    watchdog_s : float
        Command watchdog asked of the MCU in HELLO [s].
    hello_period_s : float
        HELLO is repeated this often until answered [s].
    """

    port: str
    baudrate: int = 921600
    handshake_timeout_s: float = 0.5
    link_timeout_s: float = 0.25
    watchdog_s: float = 0.25
    hello_period_s: float = 0.1

    def __post_init__(self) -> None:
        if not isinstance(self.port, str) or not self.port:
            raise ValueError(f'expected port a device path, got {self.port!r}')
        if isinstance(self.baudrate, bool) or not isinstance(self.baudrate, int) \
                or self.baudrate <= 0:
            raise ValueError(f'expected baudrate a positive integer, got {self.baudrate!r}')
        for name in ('handshake_timeout_s', 'link_timeout_s', 'watchdog_s', 'hello_period_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'expected {name} > 0 s, got {value}')
        if not 0.001 <= self.watchdog_s <= 65.535:
            raise ValueError(f'expected watchdog_s in [0.001, 65.535] s, got {self.watchdog_s}')


@dataclass(frozen=True)
class DeviceInfo:
    """What the MCU said in HELLO_ACK: versions, the watchdog it applies [s], its channels."""

    protocol_version: int
    firmware_version: int
    watchdog_s: float
    n_motors: int
    n_chambers: int
    n_links: int


@dataclass(frozen=True)
class McuCommand:
    """One write: what the motors and valves get.

    Attributes
    ----------
    motor_mode : MotorMode
    motor_position, motor_velocity, motor_torque : ndarray, shape (3,)
        POSITION target [rad] and feed-forward [rad/s]; TORQUE [N m].
    chamber_voltage : ndarray, shape (5,)
        PEA, B1..B4 valve control voltages [V].
    link_voltage : ndarray, shape (2,)
        link_1, link_2 valve control voltages [V].
    """

    motor_mode: MotorMode = MotorMode.HOLD
    motor_position: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(N_MOTORS))
    motor_velocity: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(N_MOTORS))
    motor_torque: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(N_MOTORS))
    chamber_voltage: npt.NDArray[np.float64] = field(
        default_factory=lambda: np.zeros(N_CHAMBERS))
    link_voltage: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(N_LINKS))


@dataclass(frozen=True)
class McuReading:
    """What one ``read()`` got: the newest State (None if none came), every Fault event."""

    state: State | None
    states: int
    faults: tuple[Fault, ...]


class LinkState(enum.Enum):
    CLOSED = 'closed'
    HANDSHAKE = 'handshake'
    CONNECTED = 'connected'


class McuDriver:
    """The MCU behind a serial port.

    Parameters
    ----------
    config : DriverConfig
    clock : callable, optional
        Steady clock [s] (default `time.monotonic`).
    """

    def __init__(self, config: DriverConfig,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.clock = clock
        self.state = LinkState.CLOSED
        self.info: DeviceInfo | None = None
        self.decoder = FrameDecoder()
        self.rtt_s: float | None = None
        self.tx_frames = 0
        self.tx_dropped = 0
        self._serial: serial.Serial | None = None
        self._seq = 0
        self._since = 0.0  # handshake start or last valid frame
        self._last_hello = 0.0
        self._heartbeats: dict[int, float] = {}

    @property
    def stats(self) -> DecoderStats:
        """Frames received and dropped, since the driver was made."""
        return self.decoder.stats

    @property
    def last_seq(self) -> int:
        """Sequence number of the last frame written."""
        return (self._seq - 1) & 0xFFFF

    # -- opening and closing ------------------------------------------------------------

    def connect(self) -> None:
        """Open the port and send HELLO; `read` completes the handshake (non-blocking).

        Raises
        ------
        LinkError
            If the port cannot be opened.
        """
        self.close()
        try:
            self._serial = serial.Serial(port=self.config.port, baudrate=self.config.baudrate,
                                         timeout=0, write_timeout=0, exclusive=True)
            self._serial.reset_input_buffer()  # nothing from before this session
        except (serial.SerialException, OSError, ValueError) as err:
            self._serial = None
            raise LinkError(f'cannot open {self.config.port}: {err}') from None
        self.state = LinkState.HANDSHAKE
        self.info = None
        self.decoder.reset_sequence()
        self._since = self.clock()
        self._hello(self._since)

    def open(self, poll_s: float = 0.005) -> DeviceInfo:
        """`connect`, then wait (blocking, at most ``handshake_timeout_s``) for HELLO_ACK.

        Raises
        ------
        LinkError, VersionError
        """
        self.connect()
        while self.state is LinkState.HANDSHAKE:
            time.sleep(poll_s)
            self.read()
        return self.info

    def close(self) -> None:
        """Close the port (the MCU's watchdog then makes its outputs safe)."""
        if self._serial is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                self._serial.close()
        self._serial = None
        self.state = LinkState.CLOSED

    # -- read and write --------------------------------------------------------------------

    def read(self) -> McuReading:
        """Everything the MCU sent since the last call.

        Raises
        ------
        LinkError
            The port failed, no HELLO_ACK within ``handshake_timeout_s``, or no valid frame
            within ``link_timeout_s``; the driver is closed.
        VersionError
            HELLO_ACK of another protocol version; the driver is closed.
        """
        if self._serial is None:
            raise LinkError(f'{self.config.port} is not open')
        try:
            waiting = self._serial.in_waiting
            data = self._serial.read(waiting) if waiting else b''
        except (serial.SerialException, OSError) as err:
            self.close()
            raise LinkError(f'{self.config.port}: {err}') from None
        now = self.clock()
        newest, states, faults = None, 0, []
        for frame in self.decoder.feed(data):
            message = frame.message
            if isinstance(message, HelloAck) and self.state is LinkState.HANDSHAKE:
                self._accept(message)
                self._since = now
            elif self.state is not LinkState.CONNECTED:
                continue  # whatever an old session still sends
            elif isinstance(message, State):
                newest, states = message, states + 1
                self._since = now
            elif isinstance(message, Fault):
                faults.append(message)
                self._since = now
            elif isinstance(message, HeartbeatAck):
                sent = self._heartbeats.pop(message.time_ms, None)
                if sent is not None:
                    self.rtt_s = now - sent
                self._since = now
        quiet = now - self._since
        if self.state is LinkState.HANDSHAKE:
            if quiet > self.config.handshake_timeout_s:
                self.close()
                raise LinkError(f'no HELLO_ACK from the MCU on {self.config.port} within '
                                f'{self.config.handshake_timeout_s} s')
            if now - self._last_hello >= self.config.hello_period_s:
                self._hello(now)
        elif quiet > self.config.link_timeout_s:
            self.close()
            raise LinkError(f'no valid frame from the MCU on {self.config.port} for '
                            f'{quiet * 1000:.0f} ms (link timeout '
                            f'{self.config.link_timeout_s * 1000:.0f} ms)')
        return McuReading(newest, states, tuple(faults))

    def write(self, command: McuCommand) -> int:
        """Send ``command`` (motor frame if the MCU has motors, valve frame if it has valves).

        Returns
        -------
        int
            Sequence number of the last frame sent: a State with that ``command_seq`` (or
            later) shows the MCU applied it.

        Raises
        ------
        LinkError
            Not connected, or the port failed (the driver is then closed).
        """
        if self.state is not LinkState.CONNECTED:
            raise LinkError(f'{self.config.port}: not connected to the MCU')
        messages: list[Message] = []
        if self.info.n_motors:
            messages.append(MotorCommand(int(command.motor_mode), command.motor_position,
                                         command.motor_velocity, command.motor_torque))
        if self.info.n_chambers or self.info.n_links:
            messages.append(ValveCommand(command.chamber_voltage, command.link_voltage))
        self._send(messages)
        return self.last_seq

    def heartbeat(self) -> None:
        """Send a HEARTBEAT; its answer updates `rtt_s` (the link's round trip time)."""
        now = self.clock()
        stamp = int(now * 1000.0) & 0xFFFFFFFF
        self._heartbeats = {k: v for k, v in self._heartbeats.items() if now - v < 5.0}
        self._heartbeats[stamp] = now
        self._send([Heartbeat(stamp)])

    def inject_fault(self, kind: int, channel: int = 0, value: float = 0.0,
                     duration_s: float = 0.0) -> None:
        """Ask a simulated MCU to fake a fault (`inflarm_hw.mcu_protocol.FaultKind`)."""
        self._send([FaultInject(int(kind), channel, value, duration_s)])

    # -- internals ----------------------------------------------------------------------------

    def _accept(self, ack: HelloAck) -> None:
        if ack.protocol_version != PROTOCOL_VERSION:
            self.close()
            raise VersionError(
                f'the MCU on {self.config.port} speaks protocol version {ack.protocol_version}'
                f' (firmware {ack.firmware_version}); this bridge speaks {PROTOCOL_VERSION}')
        self.info = DeviceInfo(ack.protocol_version, ack.firmware_version,
                               ack.watchdog_ms / 1000.0, ack.n_motors, ack.n_chambers,
                               ack.n_links)
        self.state = LinkState.CONNECTED

    def _hello(self, now: float) -> None:
        self._last_hello = now
        # a leading delimiter ends whatever partial frame the MCU holds
        self._send([Hello(PROTOCOL_VERSION, round(self.config.watchdog_s * 1000))], lead=True)

    def _send(self, messages: list[Message], lead: bool = False) -> None:
        if self._serial is None:
            raise LinkError(f'{self.config.port} is not open')
        data = b'\x00' if lead else b''
        for message in messages:
            data += encode_frame(message, self._seq)
            self._seq = (self._seq + 1) & 0xFFFF
        try:
            written = self._serial.write(data)
        except serial.SerialTimeoutException:
            written = 0
        except (serial.SerialException, OSError) as err:
            self.close()
            raise LinkError(f'{self.config.port}: {err}') from None
        self.tx_frames += len(messages)
        if written is not None and written < len(data):
            self.tx_dropped += 1  # the line's buffer is full: the MCU is not reading
