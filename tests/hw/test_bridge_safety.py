"""The hardware bridge's safety core (inflarm_hw.bridge), without ROS or a serial line."""

import math

import numpy as np
import pytest

from inflarm_hw.bridge import (
    BridgeConfig,
    SafetySupervisor,
    check_motor_command,
    check_pressure_command,
)
from inflarm_hw.driver import DeviceInfo
from inflarm_hw.mcu_protocol import MotorMode, State
from inflarm_hw.valve import pressure_to_voltage, voltage_to_pressure
from inflarm_model.link import min_pressure_for_moment
from inflarm_msgs_json import LinkStatus

BOTH = DeviceInfo(1, 1, 0.25, 3, 5, 2)
Q0 = (0.0, 0.6, -1.2)


class Bench:
    """A supervisor on a fake clock with noisy pressure readings, as from the sim MCU."""

    def __init__(self, device=BOTH, **config) -> None:
        self.sup = SafetySupervisor(BridgeConfig(**config), device)
        self.now = 100.0
        self.seq = 0
        self.rng = np.random.default_rng(7)
        self.chambers = np.zeros(5)
        self.links = np.array([50e3, 50e3])
        self.motors = np.array(Q0)
        self.stuck = {}

    def state(self, command_seq=None):
        noise = self.rng.normal(0.0, 20.0, 7)
        readings = np.concatenate([self.chambers, self.links]) + noise
        for channel, value in self.stuck.items():
            readings[channel] = value
        return State(int(self.now * 1000), 1, self.seq if command_seq is None else command_seq,
                     0, 0, self.motors, np.zeros(3), np.zeros(3), readings[:5], readings[5:])

    def tick(self, dt=0.01, enabled=True, command_seq=None):
        """One bridge cycle: a State, then an output (written as the next sequence number)."""
        self.now += dt
        self.sup.on_state(self.state(command_seq), self.now)
        out = self.sup.output(self.now, enabled)
        self.seq += 1
        self.sup.sent(self.seq)
        return out

    def command(self, **pressures):
        self.sup.on_pressure_command(pressures, self.now)

    def move(self, *q):
        self.sup.on_motor_command(['joint_1', 'joint_2', 'joint_3'], q, [], self.now)


def chamber_pressures(out):
    return voltage_to_pressure(out.chamber_voltage)


def test_bad_configs_are_refused_with_their_name():
    for kwargs, message in [
        ({'cmd_timeout_s': 600.0}, r'cmd_timeout_s in \(0, 2\] s \(a fail-safe\)'),
        ({'chamber_over_pressure': 90e3}, 'chamber_pressure_max < chamber_over_pressure'),
        ({'link_pressure': (50e3, 65e3)}, 'link_pressure within'),
        ({'safe_motors': 'coast'}, 'safe_motors one of'),
        ({'frozen_sensor_s': 0.01}, 'frozen_sensor_s 0'),
        ({'position_min': (0.0, 0.0, 4.0)}, 'position_min < position_max'),
        ({'pressure_rate': math.nan}, 'finite pressure_rate'),
        ({'chamber_pressure_max': 2e6, 'chamber_over_pressure': 3e6}, 'valve range'),
    ]:
        with pytest.raises(ValueError, match=message):
            BridgeConfig(**kwargs)


def test_motor_commands_are_checked_by_name():
    config = BridgeConfig()
    target = check_motor_command(['joint_3', 'joint_1'], [-1.0, 0.2], [0.1, 5.0], config)
    assert target.position == {2: -1.0, 0: 0.2}
    assert target.velocity == {2: 0.1, 0: 1.0}
    assert target.clamped == ('joint_1 velocity 5.000 rad/s clamped to 1.000',)
    for args, message in [
        ((['elbow'], [0.1], []), r"unknown joints \['elbow'\]"),
        ((['joint_1'], [math.nan], []), 'joint_1 position nan is not finite'),
        ((['joint_2'], [4.0], []), r'joint_2 position 4.0000 rad outside the joint limits'),
        ((['joint_1'], [0.1], [math.inf]), 'joint_1 velocity inf is not finite'),
        ((['joint_1', 'joint_1'], [0.1, 0.2], []), 'named twice'),
        ((['joint_1'], [0.1, 0.2], []), '2 positions for 1 joints'),
        (([], [], []), 'no joint named'),
    ]:
        with pytest.raises(ValueError, match=message):
            check_motor_command(*args, config)


def test_pressure_commands_beyond_the_chamber_range_are_rejected_whole():
    target = check_pressure_command({'B1': 100e3, 'PEA': 0.0, 'B2': 30e3}, BridgeConfig())
    assert target.pressure == {1: 100e3, 0: 0.0, 2: 30e3}
    for bad, match in (({'B1': 120e3}, 'B1 at 120000 Pa is outside 0..100000 Pa'),
                       ({'PEA': -500.0}, 'PEA at -500 Pa is outside'),
                       ({'B9': 1.0}, r"unknown chambers \['B9'\]"),
                       ({'B1': math.nan}, 'B1 at nan Pa is outside')):
        with pytest.raises(ValueError, match=match):
            check_pressure_command(bad, BridgeConfig())
    bench = Bench()
    with pytest.raises(ValueError):
        bench.command(B1=150e3)
    with pytest.raises(ValueError):
        bench.command(B7=1.0)
    assert bench.sup.rejected == 2 and bench.sup.clamped == 0


def test_outputs_are_safe_until_the_first_command_and_then_follow_with_slew_limits():
    bench = Bench(pressure_rate=100e3, max_velocity=0.5, cmd_timeout_s=2.0)
    out = bench.tick()
    assert out.motor_mode == MotorMode.HOLD
    np.testing.assert_allclose(chamber_pressures(out), 0.0)
    np.testing.assert_allclose(voltage_to_pressure(out.link_voltage), [50e3, 50e3])
    assert bench.sup.status('active', 'connected').reason.startswith('no motor_position_command')
    bench.command(B1=50e3)
    bench.move(0.5, 0.6, -1.2)
    pressures, positions = [], []
    for _ in range(110):
        out = bench.tick(0.01)
        pressures.append(chamber_pressures(out)[1])
        positions.append(out.motor_position[0])
        bench.motors = out.motor_position
    assert out.motor_mode == MotorMode.POSITION
    # 100 kPa/s and 0.5 rad/s: 1 kPa and 5 mrad per 10 ms step, then the targets
    np.testing.assert_allclose(np.diff(pressures)[5:40], 1e3, rtol=1e-6)
    assert pressures[-1] == pytest.approx(50e3)
    np.testing.assert_allclose(np.diff(positions)[:50], 5e-3, rtol=1e-6)
    assert positions[-1] == pytest.approx(0.5)
    assert bench.sup.status('active', 'connected').motors == 'follow'


def test_the_command_watchdog_makes_the_output_safe_and_the_mcu_confirms_it():
    bench = Bench(cmd_timeout_s=0.2)
    bench.command(B1=30e3)
    bench.move(*Q0)
    last_command = bench.now
    for _ in range(10):
        bench.tick(0.01)
    while True:
        out = bench.tick(0.01, command_seq=bench.seq - 1)  # the MCU is one frame behind
        if out.motor_mode == MotorMode.HOLD:
            break
    assert bench.now - last_command == pytest.approx(0.2, abs=0.0101)
    np.testing.assert_allclose(chamber_pressures(out), 0.0)
    np.testing.assert_allclose(voltage_to_pressure(out.link_voltage), [50e3, 50e3])
    assert bench.sup.safe_latency is None
    bench.tick(0.01, command_seq=bench.seq - 1)
    bench.tick(0.01, command_seq=bench.seq - 1)
    # confirmed two cycles after the first safe write; timed from when the watchdog fired
    assert bench.sup.safe_latency == pytest.approx(0.02, abs=1e-6)
    status = bench.sup.status('active', 'connected')
    assert (status.motors, status.valves) == ('hold', 'safe')
    assert 'no chamber_pressure_command for 0.2 s' in status.reason
    bench.command(B1=30e3)
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.POSITION


def test_inactive_means_safe_and_zero_torque_is_a_choice():
    bench = Bench(safe_motors='zero_torque')
    bench.command(B1=30e3)
    bench.move(*Q0)
    assert bench.tick(enabled=True).motor_mode == MotorMode.POSITION
    out = bench.tick(enabled=False)
    assert out.motor_mode == MotorMode.OFF
    np.testing.assert_allclose(chamber_pressures(out), 0.0)
    assert bench.sup.status('inactive', 'connected').motors == 'zero_torque'


@pytest.mark.parametrize('safe_motors, mode', [('hold', MotorMode.HOLD),
                                                ('zero_torque', MotorMode.OFF)])
def test_motor_fields_the_mode_does_not_use_are_what_the_spec_says(safe_motors, mode):
    # inflarm_hw/README.md, MOTOR_COMMAND: HOLD and OFF carry the measured positions
    # (information only), velocity and torque 0; POSITION no torque
    bench = Bench(safe_motors=safe_motors, max_velocity=0.5)
    out = bench.tick()  # no command yet: safe, while the motors are measured at Q0
    assert out.motor_mode == mode
    np.testing.assert_allclose(out.motor_position, Q0)
    for values in (out.motor_velocity, out.motor_torque):
        np.testing.assert_array_equal(values, 0.0)
    # POSITION: feed-forward as commanded (clamped), the slew rate where the slew limits
    bench.sup.on_motor_command(['joint_1', 'joint_2', 'joint_3'], [0.0, 0.6, -0.7],
                               [0.2, 0.0, -0.9], bench.now)
    out = bench.tick(0.01)
    assert out.motor_mode == MotorMode.POSITION
    np.testing.assert_allclose(out.motor_position, [0.0, 0.6, -1.195])
    np.testing.assert_allclose(out.motor_velocity, [0.2, 0.0, 0.5])
    np.testing.assert_array_equal(out.motor_torque, 0.0)
    bench.sup.on_link_lost('no valid frame for 300 ms', bench.now)
    out = bench.tick()
    assert out.motor_mode == mode
    np.testing.assert_allclose(out.motor_position, Q0)
    np.testing.assert_array_equal(out.motor_velocity, 0.0)


def test_over_pressure_vents_and_latches_until_reset():
    bench = Bench()
    bench.command(B2=40e3)
    bench.move(*Q0)
    bench.tick()
    bench.chambers[2] = 140e3
    out = bench.tick()
    np.testing.assert_allclose(chamber_pressures(out), 0.0)
    assert out.motor_mode == MotorMode.HOLD
    np.testing.assert_allclose(voltage_to_pressure(out.link_voltage), [50e3, 50e3])  # chamber
    status = bench.sup.status('active', 'connected')
    assert status.latched == ('over_pressure',) and 'B2 at 1' in status.reason
    ok, message = bench.sup.reset_faults(bench.now)
    assert not ok and message.startswith('over_pressure persists: B2 at')
    bench.chambers[2] = 0.0
    bench.command(B2=40e3)
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.HOLD  # still latched, commands or not
    assert bench.sup.reset_faults(bench.now) == (True, 'reset over_pressure')
    bench.command(B2=40e3)
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.POSITION


def test_a_frozen_link_sensor_vents_the_links_too():
    bench = Bench(frozen_sensor_s=0.3, link_fault_pressure=0.0)
    bench.command(B1=30e3)
    bench.move(*Q0)
    bench.tick()
    bench.stuck[6] = 50012.5
    for _ in range(29):
        out = bench.tick(0.01)
    assert out.motor_mode == MotorMode.POSITION
    for _ in range(3):
        out = bench.tick(0.01)
    assert out.motor_mode == MotorMode.HOLD
    np.testing.assert_allclose(voltage_to_pressure(out.link_voltage), [0.0, 0.0])
    assert 'link_2 has read 50012.5 Pa' in bench.sup.faults['frozen_sensor']


def test_a_nan_reading_is_an_invalid_sensor():
    bench = Bench()
    bench.stuck[0] = math.nan
    bench.tick()
    assert 'sensor_invalid' in bench.sup.faults


def test_wrinkling_warns_then_stops_the_motion_only():
    bench = Bench()
    moment_at = {p: p * math.pi**2 * 0.055**3 / 4.0 for p in (40e3, 47e3, 55e3)}
    assert min_pressure_for_moment(moment_at[47e3], 0.055) == pytest.approx(47e3)
    bench.command(B1=30e3)
    bench.move(*Q0)
    bench.tick()
    for pressure, motors, fault in [(40e3, MotorMode.POSITION, None),
                                    (47e3, MotorMode.POSITION, 'wrinkle_risk'),
                                    (55e3, MotorMode.HOLD, 'wrinkle_stop'),
                                    (40e3, MotorMode.POSITION, None)]:
        bench.sup.on_link_status(LinkStatus.from_moments(
            'link_1', 50e3, moment_at[40e3], moment_at[pressure]), bench.now)
        bench.command(B1=30e3)
        bench.move(*Q0)
        out = bench.tick()
        assert out.motor_mode == motors, pressure
        assert chamber_pressures(out)[1] > 0.0  # the valves keep following
        assert (fault in bench.sup.faults) if fault else not any(
            f.startswith('wrinkle') for f in bench.sup.faults)
    kinds = [e.kind for e in bench.sup.drain_events()]
    assert 'wrinkle_warn' in kinds and 'wrinkle_stop' in kinds and 'wrinkle_clear' in kinds
    # a stale LinkStatus is not evidence
    bench.sup.on_link_status(LinkStatus.from_moments('link_2', 50e3, 1.0, moment_at[55e3]),
                             bench.now - 5.0)
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.POSITION


def test_a_wrinkle_stop_holds_and_names_itself_until_the_link_recovers():
    # after the first held cycle the target is dropped (a fresh command resumes); the stop must
    # still be the reason, and still hold, when zero torque is the other faults' choice
    bench = Bench(safe_motors='zero_torque')
    moment = 55e3 * math.pi**2 * 0.055**3 / 4.0
    bench.command(B1=30e3)
    bench.move(*Q0)
    bench.tick()
    bench.sup.on_link_status(LinkStatus.from_moments('link_1', 50e3, 0.0, moment), bench.now)
    for _ in range(3):
        bench.command(B1=30e3)
        assert bench.tick().motor_mode == MotorMode.HOLD
        status = bench.sup.status('active', 'connected')
        assert status.motors == 'hold' and status.reason.startswith('wrinkle_stop'), status
    bench.sup.on_link_status(LinkStatus.from_moments('link_1', 50e3, 0.0, moment / 4.0),
                             bench.now)
    bench.command(B1=30e3)
    bench.tick()
    assert bench.sup.status('active', 'connected').reason == (
        'waiting for a fresh motor_position_command')
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.POSITION


def test_link_loss_is_safe_until_the_same_mcu_is_back():
    bench = Bench()
    bench.command(B1=30e3)
    bench.move(*Q0)
    bench.tick()
    bench.sup.on_link_lost('no valid frame for 300 ms', bench.now)
    out = bench.tick()
    assert out.motor_mode == MotorMode.HOLD
    assert bench.sup.faults == {'link_lost': 'no valid frame for 300 ms'}
    with pytest.raises(ValueError, match='came back with other channels'):
        bench.sup.on_link_restored(DeviceInfo(1, 1, 0.25, 0, 5, 0), bench.now)
    bench.sup.on_link_restored(BOTH, bench.now)
    bench.command(B1=30e3)
    bench.move(*Q0)
    assert bench.tick().motor_mode == MotorMode.POSITION


def test_an_sra_only_mcu_has_no_motor_output():
    bench = Bench(DeviceInfo(1, 1, 0.25, 0, 5, 0))
    with pytest.raises(ValueError, match='no motors'):
        bench.move(*Q0)
    bench.command(PEA=10e3)
    bench.tick()
    out = bench.tick()
    assert bench.sup.status('active', 'connected').motors == 'none'
    assert chamber_pressures(out)[0] > 0.0


def test_link_set_points_are_checked():
    bench = Bench(pressure_rate=20e3)
    bench.tick()
    bench.sup.set_link_pressure([40e3, 45e3])
    np.testing.assert_allclose(voltage_to_pressure(bench.tick(0.2).link_voltage),
                               [48e3, 48e3], rtol=1e-6)  # 20 kPa/s over the 0.1 s cap
    with pytest.raises(ValueError, match='link_pressure within'):
        bench.sup.set_link_pressure([5e3, 45e3])
    assert pressure_to_voltage(45e3) > 0.0
