"""The simulated MCU keeps the protocol points of the firmware checklist (inflarm_hw/README.md):
sequence numbers at a session start, ``command_seq`` before a command, one watchdog for both
command types, FAULT channel and value per code, the rate limit, a HELLO of another version.

The core (`SimMcu.receive` and `SimMcu.step`) with the time given, so every window is exact."""

import math
import pathlib

import numpy as np
import pytest

from inflarm_hw.mcu_protocol import (
    Fault,
    FaultCode,
    FaultInject,
    FaultKind,
    FrameDecoder,
    Heartbeat,
    HeartbeatAck,
    Hello,
    HelloAck,
    MessageType,
    MotorCommand,
    MotorMode,
    State,
    StatusFlag,
    ValveCommand,
    encode_frame,
)
from inflarm_hw.sim_mcu import FAULT_REPEAT_S
from mcu_harness import Q0, make_mcu

DT = 0.02


class Host:
    """The host's side of one SimMcu: numbered frames in, decoded frames out."""

    def __init__(self, plants='both', **params) -> None:
        self.mcu = make_mcu(plants, **params)
        self.decoder = FrameDecoder()
        self.seq = 100  # any start: the MCU takes the host's numbering as it comes
        self.now = 10.0

    def send(self, *messages):
        data = b''
        for message in messages:
            data += encode_frame(message, self.seq)
            self.seq += 1
        return self.decoder.feed(self.mcu.receive(data, self.now))

    def step(self, seconds=DT):
        frames = []
        for _ in range(max(1, round(seconds / DT))):
            self.now += DT
            frames += self.decoder.feed(self.mcu.step(DT, self.now))
        return frames


def messages(frames, cls):
    return [f.message for f in frames if isinstance(f.message, cls)]


def valves():
    return ValveCommand((1.0,) * 5, (0.56, 0.56))


def position():
    return MotorCommand(MotorMode.POSITION, tuple(Q0), (0.0,) * 3)


def test_every_reply_to_a_hello_is_numbered_from_zero_and_the_host_counts_no_loss():
    host = Host()
    first = host.send(Hello(watchdog_ms=250))
    assert [(f.seq, type(f.message)) for f in first] == [(0, HelloAck)]
    states = host.step(0.1)
    assert [f.seq for f in states] == [1, 2, 3, 4, 5]
    again = host.send(Hello(watchdog_ms=250))  # a new session: numbered from 0 again
    assert [f.seq for f in again] == [0]
    assert [f.seq for f in host.step()] == [1]
    # the restart at HELLO_ACK is no loss for the host's decoder, nor a HELLO for the MCU's
    assert host.decoder.stats.lost == 0
    host.seq += 7  # seven host frames lost after the HELLO
    host.send(valves())
    assert messages(host.step(), State)[-1].rx_lost == 7


def test_command_seq_is_the_hellos_until_a_command_is_applied():
    host = Host()
    hello_seq = host.seq
    host.send(Hello())
    (state,) = messages(host.step(), State)
    assert state.command_seq == hello_seq
    assert state.status & StatusFlag.WATCHDOG  # safe: no command yet in this session
    host.send(Heartbeat(1))  # not a command: command_seq stays
    assert messages(host.step(), State)[-1].command_seq == hello_seq
    command_seq = host.seq
    host.send(valves())
    state = messages(host.step(), State)[-1]
    assert state.command_seq == command_seq and not state.status & StatusFlag.WATCHDOG
    # a new session forgets the commands of the old one, and starts safe
    hello_seq = host.seq
    host.send(Hello())
    state = messages(host.step(), State)[-1]
    assert state.command_seq == hello_seq and state.status & StatusFlag.WATCHDOG
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 0.0)


@pytest.mark.parametrize('command', [valves, position], ids=['valves only', 'motors only'])
def test_one_watchdog_is_fed_by_either_command_type_not_by_heartbeats(command):
    host = Host()
    host.send(Hello(watchdog_ms=100))
    for _ in range(25):  # 0.5 s, a command every 40 ms
        host.send(command())
        frames = host.step(0.04)
        assert not messages(frames, Fault)
        assert not messages(frames, State)[-1].status & StatusFlag.WATCHDOG
    frames = []
    for _ in range(5):  # no command for 200 ms > 100 ms; heartbeats do not feed it
        host.send(Heartbeat(0))
        frames += host.step(0.04)
    (fault,) = messages(frames, Fault)
    assert fault.code == FaultCode.WATCHDOG and fault.channel == 0
    assert 0.1 < fault.value <= 0.1 + DT + 1e-9  # seconds since the last command
    assert messages(frames, State)[-1].status & StatusFlag.WATCHDOG


def test_a_second_watchdog_trip_within_a_second_is_reported_too():
    host = Host()
    host.send(Hello(watchdog_ms=50))
    trips = []
    for _ in range(3):  # three trips within 0.5 s
        host.send(valves())
        trips += [f for f in messages(host.step(0.1), Fault) if f.code == FaultCode.WATCHDOG]
    assert len(trips) == 3


def test_an_invalid_command_is_ignored_reported_per_frame_type_and_rate_limited():
    host = Host()
    host.send(Hello(watchdog_ms=100))
    host.send(valves())
    good = host.seq - 1
    host.step()
    nan_valves = ValveCommand((math.nan,) + (1.0,) * 4, (0.56, 0.56))
    nan_motors = MotorCommand(MotorMode.POSITION, (math.nan, 0.6, -1.2))
    unknown_mode = MotorCommand(9, tuple(Q0))
    faults = messages(host.send(nan_valves, nan_motors, unknown_mode, nan_valves), Fault)
    # one per (code, channel): the channel is the type of the ignored frame
    assert [(f.code, f.channel, f.value) for f in faults] == [
        (FaultCode.COMMAND_INVALID, MessageType.VALVE_COMMAND, 0.0),
        (FaultCode.COMMAND_INVALID, MessageType.MOTOR_COMMAND, 0.0)]
    frames = host.step(0.06)
    assert messages(frames, State)[-1].command_seq == good  # none of them applied
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 1.0)  # the last valid command
    # they did not feed the watchdog: it fires 100 ms after the last valid command
    frames = host.step(0.06)
    assert [f.code for f in messages(frames, Fault)] == [FaultCode.WATCHDOG]
    # the same (code, channel) within FAULT_REPEAT_S: not reported; after it, reported again
    assert messages(host.send(nan_valves), Fault) == []
    host.now += FAULT_REPEAT_S
    assert [f.channel for f in messages(host.send(nan_valves), Fault)] == [
        MessageType.VALVE_COMMAND]
    host.send(Hello())  # a new session does not restart the window
    assert messages(host.send(nan_valves), Fault) == []


def test_fields_a_mode_does_not_use_are_ignored():
    host = Host()
    host.send(Hello(watchdog_ms=250))
    # HOLD with whatever in its fields (the bridge sends 0), TORQUE unused
    hold = MotorCommand(MotorMode.HOLD, (math.nan, 5.0, -5.0), (math.inf,) * 3, (math.nan,) * 3)
    assert messages(host.send(hold), Fault) == []
    held = host.mcu.arm.target.copy()
    host.step(0.2)
    np.testing.assert_allclose(host.mcu.arm.target, held)  # held where the hold began
    state = messages(host.step(), State)[-1]
    assert state.command_seq == host.seq - 1 and not state.status & StatusFlag.WATCHDOG
    # POSITION uses position and velocity, not torque
    target = tuple(np.add(Q0, 0.05))
    follow = MotorCommand(MotorMode.POSITION, target, (0.0,) * 3, (math.nan,) * 3)
    assert messages(host.send(follow), Fault) == []
    assert messages(host.step(), State)[-1].status & StatusFlag.MOTORS_ACTIVE


def test_torque_is_unsupported_the_motors_hold_and_the_fault_is_rate_limited():
    host = Host()
    host.send(Hello(watchdog_ms=100))
    torque = MotorCommand(MotorMode.TORQUE, torque=(1.0, 2.0, 3.0))
    faults = []
    for _ in range(10):  # 0.4 s of torque commands
        faults += messages(host.send(torque), Fault)
        faults += messages(host.step(0.04), Fault)
    assert [(f.code, f.channel, f.value) for f in faults] == [
        (FaultCode.MODE_UNSUPPORTED, 0, float(MotorMode.TORQUE))]
    state = messages(host.step(), State)[-1]
    # applied as HOLD: it fed the watchdog and its number is the command_seq
    assert state.command_seq == host.seq - 1
    assert not state.status & (StatusFlag.WATCHDOG | StatusFlag.MOTORS_ACTIVE)


def test_a_command_before_hello_is_ignored_and_reported_per_frame_type():
    host = Host()
    faults = messages(host.send(valves(), position(), valves()), Fault)
    assert [(f.code, f.channel) for f in faults] == [
        (FaultCode.NO_SESSION, MessageType.VALVE_COMMAND),
        (FaultCode.NO_SESSION, MessageType.MOTOR_COMMAND)]
    assert host.step() == []  # no session: no STATE
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 0.0)


def test_a_hello_of_another_version_ends_the_session_safe_and_opens_none():
    host = Host()
    host.send(Hello(watchdog_ms=100))
    host.send(valves(), position())
    host.step()
    frames = host.send(Hello(protocol_version=2, watchdog_ms=100))
    assert [f.seq for f in frames] == [0, 1]
    ack, fault = (f.message for f in frames)
    # its own version and firmware, no watchdog applied (no session), its channels
    assert ack == HelloAck(1, 1, 0, 3, 5, 2)
    assert (fault.code, fault.channel, fault.value) == (FaultCode.VERSION_MISMATCH, 0, 2.0)
    assert host.step(0.2) == []  # no session: no STATE, no watchdog event
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 0.0)  # vented
    assert host.mcu.motor_mode == MotorMode.HOLD
    faults = messages(host.send(valves()), Fault)
    assert [(f.code, f.channel) for f in faults] == [
        (FaultCode.NO_SESSION, MessageType.VALVE_COMMAND)]
    # every such HELLO is answered alike (not rate-limited)
    frames = host.send(Hello(protocol_version=2, watchdog_ms=100))
    assert [(f.seq, type(f.message)) for f in frames] == [(0, HelloAck), (1, Fault)]


def test_fault_inject_that_cannot_be_done_says_its_channel_and_kind():
    host = Host()
    host.send(Hello())
    (fault,) = messages(host.send(FaultInject(FaultKind.STICK_SENSOR, 9)), Fault)
    assert (fault.code, fault.channel, fault.value) == (
        FaultCode.INJECTION_UNSUPPORTED, 9, float(FaultKind.STICK_SENSOR))
    real = Host(allow_injection=False)
    real.send(Hello())
    (fault,) = messages(real.send(FaultInject(FaultKind.SILENT, 0, 0.0, 1.0)), Fault)
    assert (fault.code, fault.channel, fault.value) == (
        FaultCode.INJECTION_UNSUPPORTED, 0, float(FaultKind.SILENT))


def test_channels_the_mcu_lacks_are_ignored_but_every_voltage_must_be_finite():
    host = Host('sra')
    host.send(Hello())
    # no motors: a MOTOR_COMMAND is taken as it is, unread (the bridge sends none)
    assert messages(host.send(MotorCommand(9, (math.nan,) * 3)), Fault) == []
    assert messages(host.step(), State)[-1].command_seq == host.seq - 1
    # no links: their voltages are ignored, but a non-finite one makes the frame invalid
    assert messages(host.send(ValveCommand((1.0,) * 5, (7.0, 7.0))), Fault) == []
    (fault,) = messages(host.send(ValveCommand((2.0,) * 5, (math.nan, 0.0))), Fault)
    assert (fault.code, fault.channel) == (FaultCode.COMMAND_INVALID, MessageType.VALVE_COMMAND)
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 1.0)
    assert messages(host.step(), State)[-1].link_pressure == (0.0, 0.0)


HELLO_WIRE = '00 02 01 02 07 02 01 02 fa 05 1d 81 62 e2 00'  # with the bridge's leading 00
HELLO_ACK_WIRE = '02 02 01 01 02 01 02 01 02 fa 04 03 05 02 05 32 e3 fc 81 00'
HEARTBEAT_WIRE = '02 03 02 08 09 04 03 02 01 fd 21 eb cf 00'
HEARTBEAT_ACK_WIRE = '02 04 02 01 09 04 03 02 01 2c 79 21 e2 00'


def test_the_readme_handshake_and_heartbeat_bytes():
    readme = (pathlib.Path(__file__).resolve().parents[2] / 'inflarm_hw' / 'README.md'
              ).read_text()
    text = ' '.join(readme.split())
    for wire in (HELLO_WIRE, HELLO_ACK_WIRE, HEARTBEAT_WIRE, HEARTBEAT_ACK_WIRE):
        assert f'`{wire}`' in text
    assert bytes.fromhex(HELLO_WIRE) == b'\x00' + encode_frame(Hello(1, 250), 7)
    assert bytes.fromhex(HEARTBEAT_WIRE) == encode_frame(Heartbeat(0x01020304), 8)
    mcu = Host().mcu
    assert mcu.receive(bytes.fromhex(HELLO_WIRE), 10.0) == bytes.fromhex(HELLO_ACK_WIRE)
    assert mcu.receive(bytes.fromhex(HEARTBEAT_WIRE), 10.001) == bytes.fromhex(
        HEARTBEAT_ACK_WIRE)
    # a heartbeat outside a session is answered too
    assert messages(Host().send(Heartbeat(5)), HeartbeatAck) == [HeartbeatAck(5)]


def test_a_reconnect_after_silence_starts_a_fresh_safe_session():
    host = Host()
    host.send(Hello(watchdog_ms=100))
    host.send(valves(), position())
    host.step()
    frames = host.step(0.2)  # the host goes silent: the watchdog trips, STATE goes on
    assert [f.code for f in messages(frames, Fault)] == [FaultCode.WATCHDOG]
    assert len(messages(frames, State)) == 10
    assert messages(frames, State)[-1].status == StatusFlag.SESSION | StatusFlag.WATCHDOG
    # a half frame on the line (counted in the old session), then the bridge's 00 + HELLO
    half = encode_frame(valves(), host.seq)[:20]
    host.seq += 1
    host.decoder.feed(host.mcu.receive(half, host.now))
    assert messages(host.step(), State)[-1].rx_errors == 0  # still waiting for its end
    host.decoder.feed(host.mcu.receive(b'\x00', host.now))
    assert messages(host.step(), State)[-1].rx_errors == 1
    host.decoder.feed(host.mcu.receive(half, host.now))
    hello_seq = host.seq
    frames = host.decoder.feed(host.mcu.receive(
        b'\x00' + encode_frame(Hello(watchdog_ms=100), hello_seq), host.now))
    host.seq += 1
    assert [(f.seq, type(f.message)) for f in frames] == [(0, HelloAck)]
    state = messages(host.step(), State)[-1]
    assert (state.rx_errors, state.rx_lost, state.command_seq) == (0, 0, hello_seq)
    assert state.status == StatusFlag.SESSION | StatusFlag.WATCHDOG
    np.testing.assert_array_equal(host.mcu.chamber_voltage, 0.0)
    assert host.mcu.motor_mode == MotorMode.HOLD
    host.send(valves())
    state = messages(host.step(), State)[-1]
    assert state.command_seq == host.seq - 1 and state.status == StatusFlag.SESSION
