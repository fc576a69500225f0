"""hw_bridge + sim_mcu as real processes over a real pty, through DDS: topics, lifecycle and every
safety behaviour under injected faults, with the time from the fault to the safe output printed.
"""

import os
import re
import signal
import time

from lifecycle_msgs.msg import Transition
import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from bridge_rig import MOTORS, Rig
from inflarm_model.elastostatics import motor_torques
from inflarm_model.kinematics import FlexibleArm
from inflarm_msgs_json import PressureCommand
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import SENSOR_QOS

pytestmark = pytest.mark.system
Q0 = [0.0, 0.6, -1.2]


def report(capsys, text: str) -> None:
    with capsys.disabled():
        print(f'\n[hw_bridge] {text}')


def latency_ms(status) -> str:
    return 'n/a' if status.safe_latency is None else f'{status.safe_latency * 1000:.0f} ms'


def test_the_bridge_carries_both_robots_and_its_watchdog_makes_them_safe(
        node_processes, executor, tmp_path, capsys):
    rig = Rig(node_processes, executor, tmp_path, bridge={'cmd_timeout_s': 0.3})
    rig.wait_status(lambda s: s.state == 'active' and s.link == 'connected'
                    and s.reason.startswith('no motor_position_command yet'))
    # the same topics and types as arm_sim and sra_sim
    rig.pressures, rig.motors = {'PEA': 20e3, 'B3': 30e3, 'B4': 30e3}, [0.1, 0.6, -1.1]
    rig.wait_status(lambda s: (s.motors, s.valves) == ('follow', 'follow'))
    assert rig.run(lambda: abs(rig.chamber('B3') - 30e3) < 1e3
                   and abs(rig.joints[-1].position[0] - 0.1) < 1e-3, 15.0), rig.chambers[-1:]
    joints = rig.joints[-1]
    assert list(joints.name) == MOTORS
    # effort: the torque each motor applies, minus the load torque tau_m of eq. (6)
    springs = []
    rig.probe.create_subscription(JointState, 'spring_states_truth', springs.append,
                                  SENSOR_QOS)
    assert rig.run(lambda: len(springs) > 0, 5.0)
    q = FlexibleArm.assemble_q(rig.joints[-1].position, springs[-1].position)
    expected = -motor_torques(FlexibleArm(0.6, 0.03), q, [0.0, 10.0, -15.0])
    np.testing.assert_allclose(rig.joints[-1].effort, expected, atol=0.15)
    np.testing.assert_allclose(list(rig.links[-1].values()), [50e3, 50e3], atol=300.0)
    assert rig.run(lambda: len(rig.diagnostics) >= 2, 5.0)
    (diagnostic,) = rig.diagnostics[-1][1].status
    assert diagnostic.message.startswith('active, link connected, motors follow')
    assert {kv.key for kv in diagnostic.values} >= {'bad_frames', 'rtt_ms', 'safe_latency_ms'}

    # rejected and clamped commands: reported, and the last valid command stays in force
    rig.motors = None  # (COMMAND_QOS keeps only the newest command: one at a time)
    rig.motor_pub.publish(JointState(name=MOTORS, position=[float('nan'), 0.6, -1.1]))
    rig.wait_status(lambda s: s.rejected >= 1)
    rig.motor_pub.publish(JointState(name=['joint_2'], position=[7.0]))
    rig.wait_status(lambda s: s.rejected >= 2)
    rig.pressures = None
    rig.pressure_pub.publish(to_string_msg(PressureCommand(
        chambers={'PEA': 20e3, 'B3': 30e3, 'B4': 150e3})))  # over the chamber rating
    rig.wait_status(lambda s: s.rejected >= 3)
    rig.pressures = {'PEA': 20e3, 'B3': 30e3, 'B4': 30e3}
    rig.motor_pub.publish(JointState(name=['joint_1'], position=[0.1], velocity=[5.0]))
    rig.wait_status(lambda s: s.clamped >= 1)  # the feed-forward, to the slew limit
    rig.motors = [0.1, 0.6, -1.1]
    # one warning per kind every 2 s: each kind is logged, the joint_2 one is counted
    assert rig.run(lambda: 'joint_1 position nan is not finite' in node_processes.output()
                   and 'B4 at 150000 Pa is outside 0..100000 Pa' in node_processes.output(),
                   5.0), node_processes.output()[-2000:]
    assert abs(rig.joints[-1].position[0] - 0.1) < 2e-3

    # the command watchdog: no fresh command for 0.3 s -> motors hold, chambers vent
    rig.pressures = rig.motors = None
    last = rig.last_command
    seen, status = rig.wait_status(lambda s: s.valves == 'safe' and s.motors == 'hold'
                                   and s.safe_latency is not None and 'for 0.3 s' in s.reason)
    report(capsys, f'command watchdog (0.3 s): MCU confirmed the safe output {latency_ms(status)}'
           ' after the watchdog fired (bridge clock); the test saw it '
           f'{(seen - last - 0.3) * 1000:.0f} ms after its last command + 0.3 s')
    assert rig.run(lambda: rig.chamber('B3') < 2e3, 10.0)
    held = rig.joints[-1].position[0]
    assert rig.run(lambda: False, 0.5) is False
    assert abs(rig.joints[-1].position[0] - held) < 1e-3


def test_lifecycle_transitions_command_the_safe_output_first(
        node_processes, executor, tmp_path, capsys):
    rig = Rig(node_processes, executor, tmp_path, plant='sra',
              bridge={'autostart': False})
    rig.run(lambda: False, 0.5)
    assert rig.lifecycle_state() == 'unconfigured'
    assert rig.transition(Transition.TRANSITION_CONFIGURE)
    assert rig.lifecycle_state() == 'inactive'
    rig.pressures = {'B1': 30e3}
    status = rig.wait_status(lambda s: s.state == 'inactive')[1]
    assert (status.motors, status.valves) == ('none', 'safe')
    assert rig.run(lambda: False, 0.5) is False
    assert rig.run(lambda: bool(rig.chambers), 10.0)
    assert rig.chamber('B1') < 1e3  # inactive: commands are not executed
    assert rig.transition(Transition.TRANSITION_ACTIVATE)
    rig.wait_status(lambda s: s.valves == 'follow')
    assert rig.run(lambda: rig.chamber('B1') > 25e3, 10.0)
    start = time.monotonic()
    assert rig.transition(Transition.TRANSITION_DEACTIVATE)
    seen, status = rig.wait_status(lambda s: s.valves == 'safe' and s.safe_latency is not None)
    report(capsys, f'deactivate: MCU confirmed the safe output {latency_ms(status)} after the '
           f'transition; the service returned and the status arrived after '
           f'{(seen - start) * 1000:.0f} ms')
    assert rig.run(lambda: rig.chamber('B1') < 2e3, 10.0)
    assert rig.transition(Transition.TRANSITION_CLEANUP)
    assert rig.lifecycle_state() == 'unconfigured'

    # an MCU of another protocol version: configure fails and says why
    rig.start_sim('sra', {'protocol_version': 2, 'link': str(tmp_path / 'old')}, name='old_mcu')
    rig.set_parameters('hw_bridge', [Parameter('port', value=str(tmp_path / 'old'))])
    assert not rig.transition(Transition.TRANSITION_CONFIGURE)
    assert rig.lifecycle_state() == 'unconfigured'
    assert node_processes.wait_for_output('speaks protocol version 2'), node_processes.output()
    assert rig.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
    assert rig.lifecycle_state() == 'finalized'


def test_mcu_silence_and_link_loss_are_safe_and_the_bridge_reconnects(
        node_processes, executor, tmp_path, capsys):
    rig = Rig(node_processes, executor, tmp_path, plant='sra',
              bridge={'link_timeout_s': 0.2, 'reconnect_period_s': 0.2})
    rig.pressures = {'B2': 30e3}
    rig.wait_status(lambda s: s.valves == 'follow' and s.link == 'connected', 20.0)

    # damaged bytes and CRCs are dropped, the link stays up: a fifth of the frames corrupted
    # until five have been (not for a fixed time: a busy machine sends fewer frames in it)
    rig.inject('corrupt_crc', 0, 0.2)
    status = rig.wait_status(lambda s: s.bad_frames >= 5)[1]
    assert status.link == 'connected' and status.valves == 'follow'
    rig.inject('clear')
    rig.inject('drop_bytes', 0, 0.005, 1.0)
    rig.run(lambda: False, 1.2)
    assert rig.status.link == 'connected'

    # silence: link lost, outputs safe, then the bridge reconnects by itself
    start = time.monotonic()
    rig.inject('silent', 0, 0.0, 1.0)
    seen = rig.wait_status(lambda s: s.link == 'lost' and s.valves == 'safe')[0]
    report(capsys, f'MCU silent: link lost and outputs safe {(seen - start) * 1000:.0f} ms after'
           ' the injection (link timeout 200 ms; the MCU watchdog, 250 ms, vents its valves)')
    assert 'link_lost' in rig.status.faults
    rig.wait_status(lambda s: s.link == 'connected' and s.valves == 'follow', 10.0)
    assert rig.run(lambda: rig.chamber('B2') > 25e3, 10.0)

    # the MCU goes away (the process ends) and comes back on the same link: reconnected
    sim = node_processes.group.processes['sim_mcu']
    sim.send_signal(2)
    assert sim.wait(timeout=10.0) == 0
    start = time.monotonic()
    seen = rig.wait_status(lambda s: s.link in ('lost', 'closed', 'handshake')
                           and s.valves == 'safe')[0]
    report(capsys, f'MCU gone: outputs safe {(seen - start) * 1000:.0f} ms after it exited')
    rig.start_sim('sra', name='sim_mcu_again')
    rig.wait_status(lambda s: s.link == 'connected' and s.valves == 'follow', 15.0)
    assert rig.run(lambda: rig.chamber('B2') > 25e3, 10.0)
    assert rig.lifecycle_state() == 'active'


def test_over_pressure_and_frozen_sensors_vent_and_latch_until_reset(
        node_processes, executor, tmp_path, capsys):
    rig = Rig(node_processes, executor, tmp_path, plant='both')
    rig.pressures, rig.motors = {'B1': 20e3}, Q0
    rig.wait_status(lambda s: s.valves == 'follow' and s.motors == 'follow', 20.0)

    # B1's valve delivers 160 kPa whatever it gets, long enough for the bellows (its volume
    # growing as it stretches) to pass 130 kPa (~6.6 s)
    rig.inject('over_pressure', 1, 160e3, 10.0)
    assert rig.run(lambda: rig.chamber('B1') > 130e3 or 'over_pressure' in (
        rig.status.faults), 15.0)
    crossed = time.monotonic()
    seen, status = rig.wait_status(lambda s: 'over_pressure' in s.latched
                                   and s.valves == 'safe' and s.safe_latency is not None)
    report(capsys, f'over-pressure (B1 > 130 kPa): MCU confirmed the vent '
           f'{latency_ms(status)} after the bridge saw the reading; the status reached a '
           f'subscriber {(seen - crossed) * 1000:.0f} ms after the reading did')
    assert status.motors == 'hold'
    response = rig.reset_fault()
    assert not response.success and 'over_pressure persists: B1 at' in response.message
    assert rig.run(lambda: rig.chamber('B1') < 2e3, 20.0)  # injection over, vented
    response = rig.reset_fault()
    assert response.success, response.message
    rig.wait_status(lambda s: not s.latched and s.valves == 'follow')

    start = time.monotonic()
    rig.inject('stick_sensor', 6, 0.0, 0.0)  # link_2's sensor repeats its reading
    seen, status = rig.wait_status(lambda s: 'frozen_sensor' in s.latched)
    report(capsys, f'frozen sensor (0.5 s): latched and vented {(seen - start) * 1000:.0f} ms '
           f'after the sensor stuck; MCU confirmed {latency_ms(status)} after detection')
    assert (status.motors, status.valves) == ('hold', 'safe')
    assert rig.run(lambda: rig.links[-1]['link_1'] < 40e3, 10.0)  # a link sensor: links vent
    rig.inject('clear')
    assert rig.reset_fault().success
    rig.wait_status(lambda s: not s.faults and s.valves == 'follow')
    assert rig.run(lambda: rig.links[-1]['link_1'] > 45e3, 10.0)  # re-inflated


def test_a_link_below_its_wrinkle_safe_pressure_warns_then_stops_the_motion(
        node_processes, executor, tmp_path):
    rig = Rig(node_processes, executor, tmp_path, plant='arm')
    rig.motors = Q0
    rig.wait_status(lambda s: s.motors == 'follow', 20.0)
    # M = p pi^2 r^3 / 4 (eq. 3): the moments for which 50 kPa is just above, or below, p_min
    moment = {p: p * np.pi**2 * 0.055**3 / 4.0 for p in (45e3, 55e3)}
    rig.publish_link_status('link_1', moment[45e3])
    rig.wait_status(lambda s: 'wrinkle_risk' in s.faults)
    assert rig.status.motors == 'follow'
    assert rig.run(lambda: 'wrinkle-safe minimum 45000 Pa' in node_processes.output(), 5.0)
    rig.publish_link_status('link_1', moment[55e3])
    status = rig.wait_status(lambda s: 'wrinkle_stop' in s.faults)[1]
    assert status.motors == 'hold' and status.reason.startswith('wrinkle_stop')
    rig.motors = [0.3, 0.6, -1.2]
    rig.run(lambda: False, 0.5)
    assert abs(rig.joints[-1].position[0]) < 2e-3  # motion stopped
    rig.publish_link_status('link_1', moment[45e3] / 2)
    rig.wait_status(lambda s: not s.faults and s.motors == 'follow')
    assert rig.run(lambda: abs(rig.joints[-1].position[0] - 0.3) < 2e-3, 10.0)


def test_sim_mcu_prints_its_pty_and_exits_cleanly_on_sigterm(node_processes, tmp_path):
    link = tmp_path / 'mcu'
    process = node_processes.start('inflarm_hw', 'sim_mcu',
                                   parameters={'plant': 'sra', 'link': str(link)})
    assert node_processes.wait_for_output('ready: simulated MCU'), node_processes.output()
    path = re.search(r'sim_mcu: serial port (/dev/\S+)', node_processes.output()).group(1)
    assert os.path.realpath(link) == path
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=15.0) == 0, node_processes.output()
    assert not os.path.lexists(link)
