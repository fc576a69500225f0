"""The serial link between the hardware bridge and the microcontroller (MCU): framing and messages.

Pure Python (stdlib ``struct`` and ``zlib``, the ``cobs`` package), no rclpy. The wire format is
specified for firmware authors in ``inflarm_hw/README.md`` ("MCU link protocol"); this module is
its reference implementation, used by the bridge's driver (`inflarm_hw.driver`) and by the
simulated MCU (`inflarm_hw.sim_mcu`).

A frame on the wire is ``COBS(header + payload + crc32) + 0x00``:

- header ``<BBH``: message type, flags (0), sequence number (per sender, +1 per frame, mod 2^16);
- payload: the fixed little-endian layout of the type (``LAYOUT`` of each message class);
- CRC-32 (``zlib.crc32``, IEEE 802.3: reflected, init and xor-out 0xFFFFFFFF) of header and
  payload, ``<I``;
- COBS (consistent overhead byte stuffing) removes every 0x00, which then delimits frames.

`FrameDecoder` takes arbitrary bytes and returns the valid frames; bad frames (COBS error, too
short or too long, wrong CRC, unknown type, wrong payload length) are counted and skipped, and it
resynchronises on the next 0x00. It counts the frames lost between valid ones from their
sequence numbers; a HELLO or HELLO_ACK starts a session, and with it the count afresh.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
import enum
import math
import struct
from typing import ClassVar
import zlib

from cobs import cobs

#: Version of this protocol; the MCU answers HELLO with its own and the bridge refuses others.
PROTOCOL_VERSION = 1
#: Frame delimiter on the wire.
DELIMITER = b'\x00'
HEADER = struct.Struct('<BBH')
CRC = struct.Struct('<I')
#: Largest payload of any message type [bytes].
MAX_PAYLOAD = 128
#: Largest decoded frame (header + payload + CRC) and its largest COBS encoding [bytes].
MAX_FRAME = HEADER.size + MAX_PAYLOAD + CRC.size
MAX_ENCODED = MAX_FRAME + MAX_FRAME // 254 + 1
#: Channel counts of the fixed layouts: motors, chamber valves (PEA, B1..B4), link valves.
N_MOTORS, N_CHAMBERS, N_LINKS = 3, 5, 2
#: Pressure sensor channels, as numbered in FaultInject and Fault: chambers, then links.
PRESSURE_CHANNELS = N_CHAMBERS + N_LINKS


class MessageType(enum.IntEnum):
    """Message type byte of the header."""

    HELLO = 0x01  # host -> MCU: open a session
    HELLO_ACK = 0x02  # MCU -> host
    HEARTBEAT = 0x03  # host -> MCU
    HEARTBEAT_ACK = 0x04  # MCU -> host
    MOTOR_COMMAND = 0x10  # host -> MCU
    VALVE_COMMAND = 0x11  # host -> MCU
    STATE = 0x20  # MCU -> host, periodic
    FAULT = 0x30  # MCU -> host, on an event
    FAULT_INJECT = 0x40  # host -> simulated MCU only


class MotorMode(enum.IntEnum):
    """What the motors do with a MotorCommand (one mode for all motors)."""

    OFF = 0  # zero torque
    POSITION = 1  # follow position, with the velocity as feed-forward
    TORQUE = 2  # apply the torque
    HOLD = 3  # hold the position the motors are at (brake)


class StatusFlag(enum.IntFlag):
    """Bits of State.status."""

    SESSION = 0x01  # a HELLO of the right version was accepted
    WATCHDOG = 0x02  # the command watchdog has fired: motors held, chambers vented
    MOTORS_ACTIVE = 0x04  # motors follow POSITION or TORQUE commands
    FAULT_INJECTED = 0x08  # simulated MCU only: an injected fault is active


class FaultCode(enum.IntEnum):
    """Fault.code: why the MCU reports a fault event."""

    WATCHDOG = 1  # no valid command for watchdog_ms: outputs went safe
    COMMAND_INVALID = 2  # a command with a non-finite value or an unknown mode: ignored
    MODE_UNSUPPORTED = 3  # a motor mode this MCU cannot do: motors held
    NO_SESSION = 4  # a command before a successful HELLO: ignored
    VERSION_MISMATCH = 5  # HELLO of another protocol version: no session
    INJECTION_UNSUPPORTED = 6  # FAULT_INJECT on real hardware, or an unknown kind
    PLANT = 7  # simulated MCU: the simulated arm has no equilibrium
    # channel and value of each code, and which codes are rate-limited: README "FAULT"


class FaultKind(enum.IntEnum):
    """FaultInject.kind: the faults a simulated MCU can fake."""

    CLEAR = 0  # end every injected fault
    DROP_BYTES = 1  # drop this share (value, 0-1) of the bytes it sends
    CORRUPT_CRC = 2  # corrupt the CRC of this share (value, 0-1) of the frames it sends
    SILENT = 3  # send nothing (still receives and applies commands)
    STICK_SENSOR = 4  # pressure sensor `channel` repeats its current reading
    OVER_PRESSURE = 5  # valve `channel` delivers `value` Pa whatever it is commanded


def _floats(name: str, values, count: int) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != count:
        raise ValueError(f'expected {name} of {count} numbers, got {len(out)}')
    return out


def _unsigned(name: str, value: int, bits: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 1 << bits:
        raise ValueError(f'expected {name} an integer in [0, {(1 << bits) - 1}], got {value!r}')
    return value


@dataclass(frozen=True)
class Message:
    """Base of the message payloads: a fixed ``LAYOUT`` of the dataclass fields, in order.

    Integer fields are range-checked for their wire width; float arrays are tuples of the
    layout's length. Floats are carried as they are (NaN included): receivers check them.
    """

    TYPE: ClassVar[MessageType]
    LAYOUT: ClassVar[struct.Struct]
    # field name -> number of floats, for the array fields
    ARRAYS: ClassVar[dict[str, int]] = {}
    # field name -> bit width, for the integer fields
    INTS: ClassVar[dict[str, int]] = {}

    def __post_init__(self) -> None:
        for name, count in self.ARRAYS.items():
            object.__setattr__(self, name, _floats(name, getattr(self, name), count))
        for name, bits in self.INTS.items():
            _unsigned(name, getattr(self, name), bits)

    def pack(self) -> bytes:
        """The payload bytes."""
        values: list = []
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in self.ARRAYS:
                values.extend(value)
            else:
                values.append(value)
        try:
            return self.LAYOUT.pack(*values)
        except (struct.error, OverflowError) as err:  # a float beyond float32
            raise ValueError(f'{self.TYPE.name} cannot be packed: {err}') from None

    @classmethod
    def unpack(cls, payload: bytes) -> Message:
        """The message from its payload bytes; ``ValueError`` if the length is wrong."""
        if len(payload) != cls.LAYOUT.size:
            raise ValueError(f'expected a {cls.TYPE.name} payload of {cls.LAYOUT.size} bytes, '
                             f'got {len(payload)}')
        values = list(cls.LAYOUT.unpack(payload))
        kwargs = {}
        for f in fields(cls):
            count = cls.ARRAYS.get(f.name)
            if count is None:
                kwargs[f.name] = values.pop(0)
            else:
                kwargs[f.name], values = tuple(values[:count]), values[count:]
        return cls(**kwargs)


@dataclass(frozen=True)
class Hello(Message):
    """Host -> MCU: open a session. The MCU answers HelloAck and arms its watchdog."""

    TYPE = MessageType.HELLO
    LAYOUT = struct.Struct('<HH')
    INTS = {'protocol_version': 16, 'watchdog_ms': 16}
    protocol_version: int = PROTOCOL_VERSION
    watchdog_ms: int = 250  # requested command watchdog [ms]; 0: the MCU's default


@dataclass(frozen=True)
class HelloAck(Message):
    """MCU -> host: its protocol version, the watchdog it applies and its channels."""

    TYPE = MessageType.HELLO_ACK
    LAYOUT = struct.Struct('<HHHBBBx')
    INTS = {'protocol_version': 16, 'firmware_version': 16, 'watchdog_ms': 16,
            'n_motors': 8, 'n_chambers': 8, 'n_links': 8}
    protocol_version: int
    firmware_version: int
    watchdog_ms: int
    n_motors: int
    n_chambers: int
    n_links: int


@dataclass(frozen=True)
class Heartbeat(Message):
    """Host -> MCU: link check; answered by HeartbeatAck echoing ``time_ms``."""

    TYPE = MessageType.HEARTBEAT
    LAYOUT = struct.Struct('<I')
    INTS = {'time_ms': 32}
    time_ms: int  # the host's clock [ms], mod 2^32


@dataclass(frozen=True)
class HeartbeatAck(Message):
    """MCU -> host: the ``time_ms`` of the Heartbeat it answers."""

    TYPE = MessageType.HEARTBEAT_ACK
    LAYOUT = struct.Struct('<I')
    INTS = {'time_ms': 32}
    time_ms: int


@dataclass(frozen=True)
class MotorCommand(Message):
    """Host -> MCU: what the three motors do. Feeds the MCU's command watchdog."""

    TYPE = MessageType.MOTOR_COMMAND
    LAYOUT = struct.Struct('<B3x3f3f3f')
    INTS = {'mode': 8}
    ARRAYS = {'position': N_MOTORS, 'velocity': N_MOTORS, 'torque': N_MOTORS}
    mode: int  # a MotorMode
    position: tuple[float, ...] = (0.0,) * N_MOTORS  # POSITION target [rad]
    velocity: tuple[float, ...] = (0.0,) * N_MOTORS  # POSITION feed-forward [rad/s]
    torque: tuple[float, ...] = (0.0,) * N_MOTORS  # TORQUE, applied by the motor [N m]


@dataclass(frozen=True)
class ValveCommand(Message):
    """Host -> MCU: control voltage of every valve. Feeds the MCU's command watchdog."""

    TYPE = MessageType.VALVE_COMMAND
    LAYOUT = struct.Struct('<5f2f')
    ARRAYS = {'chamber_voltage': N_CHAMBERS, 'link_voltage': N_LINKS}
    chamber_voltage: tuple[float, ...] = (0.0,) * N_CHAMBERS  # PEA, B1..B4 [V]
    link_voltage: tuple[float, ...] = (0.0,) * N_LINKS  # link_1, link_2 [V]


@dataclass(frozen=True)
class State(Message):
    """MCU -> host, every report period: sensors and the MCU's status."""

    TYPE = MessageType.STATE
    LAYOUT = struct.Struct('<IHHHH3f3f3f5f2f')
    INTS = {'time_ms': 32, 'status': 16, 'command_seq': 16, 'rx_errors': 16, 'rx_lost': 16}
    ARRAYS = {'motor_position': N_MOTORS, 'motor_velocity': N_MOTORS,
              'motor_torque': N_MOTORS, 'chamber_pressure': N_CHAMBERS,
              'link_pressure': N_LINKS}
    time_ms: int  # the MCU's clock [ms], mod 2^32
    status: int  # StatusFlag bits
    command_seq: int  # sequence number of the last command frame applied
    rx_errors: int  # bad frames received since the session opened, mod 2^16
    rx_lost: int  # frames lost (sequence gaps) since the session opened, mod 2^16
    motor_position: tuple[float, ...] = (0.0,) * N_MOTORS  # [rad]
    motor_velocity: tuple[float, ...] = (0.0,) * N_MOTORS  # [rad/s]
    motor_torque: tuple[float, ...] = (0.0,) * N_MOTORS  # applied by the motor [N m]
    chamber_pressure: tuple[float, ...] = (0.0,) * N_CHAMBERS  # gauge [Pa]
    link_pressure: tuple[float, ...] = (0.0,) * N_LINKS  # gauge [Pa]


@dataclass(frozen=True)
class Fault(Message):
    """MCU -> host: a fault event (``code``), on a channel where it applies."""

    TYPE = MessageType.FAULT
    LAYOUT = struct.Struct('<HBxf')
    INTS = {'code': 16, 'channel': 8}
    code: int  # a FaultCode
    channel: int = 0
    value: float = 0.0


@dataclass(frozen=True)
class FaultInject(Message):
    """Host -> simulated MCU: fake a fault for ``duration_s`` (0: until CLEAR)."""

    TYPE = MessageType.FAULT_INJECT
    LAYOUT = struct.Struct('<BBxxff')
    INTS = {'kind': 8, 'channel': 8}
    kind: int  # a FaultKind
    channel: int = 0  # pressure channel for STICK_SENSOR and OVER_PRESSURE
    value: float = 0.0  # share for DROP_BYTES/CORRUPT_CRC, pressure [Pa] for OVER_PRESSURE
    duration_s: float = 0.0


MESSAGES: dict[int, type[Message]] = {
    cls.TYPE: cls for cls in (Hello, HelloAck, Heartbeat, HeartbeatAck, MotorCommand,
                              ValveCommand, State, Fault, FaultInject)}
assert max(cls.LAYOUT.size for cls in MESSAGES.values()) <= MAX_PAYLOAD


def encode_frame(message: Message, seq: int, crc_xor: int = 0) -> bytes:
    """The wire bytes of one frame: ``COBS(header + payload + CRC-32) + 0x00``.

    Parameters
    ----------
    message : Message
        The payload.
    seq : int
        Sender's sequence number; taken mod 2^16.
    crc_xor : int
        XORed into the CRC (fault injection: any non-zero value makes a frame receivers drop).
    """
    raw = HEADER.pack(message.TYPE, 0, seq & 0xFFFF) + message.pack()
    raw += CRC.pack(zlib.crc32(raw) ^ (crc_xor & 0xFFFFFFFF))
    return cobs.encode(raw) + DELIMITER


@dataclass(frozen=True)
class Frame:
    """A valid frame: the sender's sequence number and the message."""

    seq: int
    message: Message


@dataclass
class DecoderStats:
    """What a FrameDecoder has seen (counts since it was made)."""

    frames: int = 0  # valid frames
    cobs_errors: int = 0  # undecodable COBS
    length_errors: int = 0  # too short, too long (also overruns without a delimiter), or a
    #                         payload of the wrong length for its type
    crc_errors: int = 0
    unknown_types: int = 0
    lost: int = 0  # frames missing between valid ones, from the sequence numbers
    bytes: int = 0  # bytes fed

    @property
    def bad_frames(self) -> int:
        """Frames counted and skipped."""
        return self.cobs_errors + self.length_errors + self.crc_errors + self.unknown_types


@dataclass
class FrameDecoder:
    """Streaming decoder: arbitrary bytes in, valid frames out.

    Bytes are buffered up to the next 0x00; each delimited chunk is decoded and checked, and a
    bad one is counted in `stats` and skipped. A chunk longer than `MAX_ENCODED` is dropped
    as it arrives (memory stays bounded), and decoding resumes after the next 0x00. Empty
    chunks (repeated delimiters) are idle fill, not errors.
    """

    stats: DecoderStats = field(default_factory=DecoderStats)
    _buffer: bytearray = field(default_factory=bytearray, repr=False)
    _overrun: bool = field(default=False, repr=False)
    _last_seq: int | None = field(default=None, repr=False)

    def reset_sequence(self) -> None:
        """Forget the last sequence number (a new session restarts the sender's count)."""
        self._last_seq = None

    #: Types that start a session: no frame counts as lost before them.
    SESSION_TYPES: ClassVar[frozenset] = frozenset({MessageType.HELLO, MessageType.HELLO_ACK})

    def feed(self, data: bytes) -> list[Frame]:
        """Decode ``data`` (any bytes, any split) and return the frames it completes."""
        self.stats.bytes += len(data)
        *complete, rest = bytes(data).split(DELIMITER)
        frames = []
        for i, chunk in enumerate(complete):
            if i == 0:
                chunk = bytes(self._buffer) + chunk
                overrun = self._overrun
                self._buffer.clear()
                self._overrun = False
                if overrun:
                    continue
            frame = self._decode(chunk)
            if frame is not None:
                frames.append(frame)
        if self._overrun:
            return frames
        if complete:
            self._buffer[:] = rest
        else:
            self._buffer += rest
        if len(self._buffer) > MAX_ENCODED:
            self.stats.length_errors += 1
            self._buffer.clear()
            self._overrun = True
        return frames

    def _decode(self, chunk: bytes) -> Frame | None:
        if not chunk:
            return None
        if len(chunk) > MAX_ENCODED:
            self.stats.length_errors += 1
            return None
        try:
            raw = cobs.decode(chunk)
        except cobs.DecodeError:
            self.stats.cobs_errors += 1
            return None
        if len(raw) < HEADER.size + CRC.size:
            self.stats.length_errors += 1
            return None
        body, (crc,) = raw[:-CRC.size], CRC.unpack(raw[-CRC.size:])
        if zlib.crc32(body) != crc:
            self.stats.crc_errors += 1
            return None
        kind, _flags, seq = HEADER.unpack(body[:HEADER.size])
        cls = MESSAGES.get(kind)
        if cls is None:
            self.stats.unknown_types += 1
            return None
        try:
            message = cls.unpack(body[HEADER.size:])
        except ValueError:
            self.stats.length_errors += 1
            return None
        if self._last_seq is not None and kind not in self.SESSION_TYPES:
            gap = (seq - self._last_seq - 1) & 0xFFFF
            if gap < 0x8000:  # else a repeat or a restart: not a loss
                self.stats.lost += gap
        self._last_seq = seq
        self.stats.frames += 1
        return Frame(seq, message)


def seq_newer_or_equal(seq: int, reference: int) -> bool:
    """Whether ``seq`` is ``reference`` or after it, in 16-bit serial number arithmetic."""
    return (seq - reference) & 0xFFFF < 0x8000


def finite(values) -> bool:
    """Whether every number in ``values`` is finite."""
    return all(math.isfinite(v) for v in values)
