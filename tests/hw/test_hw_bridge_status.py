"""hw_bridge in-process, the simulated MCU on a real pty: ``~/status`` says why while configure
keeps failing, and what the bridge is once the MCU answers and after cleanup."""

import os

import rclpy
from rclpy.parameter import Parameter
from std_msgs.msg import String

from inflarm_hw.nodes.hw_bridge import HwBridge
from inflarm_msgs_json import decode
from inflarm_msgs_json.ros.qos import LATCHED_QOS
from mcu_harness import McuThread, make_mcu
from ros_harness import spin_until


def test_the_status_says_why_configure_keeps_failing_until_the_mcu_answers(executor, tmp_path):
    link = tmp_path / 'mcu'  # no MCU behind it yet
    bridge = HwBridge(context=executor.context, parameter_overrides=[
        Parameter('port', value=str(link)), Parameter('autostart', value=True),
        Parameter('autostart_retry_s', value=0.1)])
    probe = rclpy.create_node('probe', context=executor.context)
    statuses = []
    probe.create_subscription(String, '/hw_bridge/status',
                              lambda m: statuses.append(decode(m.data)), LATCHED_QOS)
    executor.add_node(bridge)
    executor.add_node(probe)

    def failed():
        return [s for s in statuses if 'configure_failed' in s.faults]

    # repeated while configure keeps failing (at least once a second), each saying why
    assert spin_until(executor, lambda: len(failed()) >= 2, 10.0), statuses
    for status in failed():
        assert (status.state, status.link, status.motors, status.valves) == (
            'unconfigured', 'closed', 'none', 'none')
        assert status.reason.startswith(f'configure failed: cannot open {link}'), status
        assert status.latched == () and status.safe_latency is None

    mcu = McuThread(make_mcu('sra'))
    try:
        os.symlink(mcu.path, link)
        assert spin_until(executor, lambda: statuses[-1].state == 'active'
                          and statuses[-1].link == 'connected', 10.0), statuses[-1]
        assert 'configure_failed' not in statuses[-1].faults
        assert (statuses[-1].motors, statuses[-1].valves) == ('none', 'safe')  # no command yet
        bridge.trigger_deactivate()
        bridge.trigger_cleanup()
        assert spin_until(executor, lambda: statuses[-1].state == 'unconfigured', 5.0)
        assert (statuses[-1].link, statuses[-1].faults, statuses[-1].reason) == (
            'closed', (), 'unconfigured: no MCU')
    finally:
        mcu.close()
