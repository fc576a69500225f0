"""The launcher's process group: a node that dies or hangs is reported with its last lines."""

import io
import os
import re
import shutil
import sys

import pytest

from inflarm_bringup import launcher
from inflarm_bringup.processes import NodeProcess, ProcessGroup, is_installed
from inflarm_bringup.systems import VISUALIZATION_PACKAGES
from ros_harness import wait_until

pytestmark = pytest.mark.system


def test_a_node_that_dies_is_reported_with_its_exit_code_and_last_lines(domain_id, capsys):
    output = io.StringIO()
    group = ProcessGroup(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)), output=output)
    group.start('bag_recorder', NodeProcess('inflarm_hw', 'bag_recorder').command())
    assert wait_until(lambda: group.first_exited() == 'bag_recorder', 20.0)
    assert group.stop(grace_s=5.0) == {'bag_recorder': 1}
    report = group.describe('bag_recorder', 'exited with code 1')
    assert report.startswith('[launch] bag_recorder exited with code 1; its last output:')
    assert "cannot start: parameter 'topics' is required" in report
    assert 'Traceback' not in output.getvalue()


def test_a_node_that_hangs_is_killed_and_reported(domain_id, capsys):
    group = ProcessGroup(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)), output=io.StringIO())
    hang = ('import signal, sys, time; signal.pthread_sigmask(signal.SIG_UNBLOCK, '
            '{signal.SIGINT}); signal.signal(signal.SIGINT, signal.SIG_IGN); '
            "print('stuck', flush=True); time.sleep(60)")
    group.start('stuck', [sys.executable, '-c', hang])
    assert wait_until(lambda: 'stuck' in ''.join(group.last_lines['stuck']), 20.0)
    codes = group.stop(grace_s=0.5)
    assert codes['stuck'] < 0  # killed
    assert '[launch] stuck did not stop within 0.5 s of SIGINT: killed' in capsys.readouterr().err


@pytest.mark.parametrize('namespace', [[], ['-r', '__ns:=/bridged']])
def test_overrides_win_over_every_parameter_file_in_any_namespace(namespace):
    # elastostatic_ik: the shared /** inflatable_arm.yaml, then its own YAML, which sets
    # gain_per_s; a -p after a /** file would lose to that YAML (rcl applies keys in the order
    # they first appear).
    import rclpy
    from rclpy.node import Node

    node = NodeProcess('inflarm_control', 'elastostatic_ik', parameters={'gain_per_s': 7.5},
                       shared_params=(('inflarm_model', 'inflatable_arm.yaml'),))
    context = rclpy.Context()
    rclpy.init(args=['x', *node.ros_arguments(), *namespace], context=context)
    try:
        probe = Node('elastostatic_ik', context=context)
        assert probe.declare_parameter('gain_per_s', 1.0).value == 7.5
        assert probe.declare_parameter('arm.link_length_m', 1.0).value == 0.6  # shared file
        probe.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_rviz_without_a_jazzy_install_is_refused_naming_what_is_missing(capsys):
    missing = [p for p in VISUALIZATION_PACKAGES if not is_installed(p)]
    if not missing:
        pytest.skip('robot_state_publisher, tf2_ros and rviz2 are installed here')
    with pytest.raises(SystemExit) as exited:
        launcher.main(['sim', '--rviz', '--duration', '1'])
    assert exited.value.code == 2
    assert f'--rviz needs {", ".join(missing)} from a ROS 2 Jazzy install' in (
        capsys.readouterr().err)


def test_rviz_is_refused_in_process(capsys):
    with pytest.raises(SystemExit) as exited:
        launcher.main(['sim', '--rviz', '--in-process'])
    assert exited.value.code == 2
    assert 'not with --in-process' in capsys.readouterr().err


@pytest.mark.skipif(shutil.which('gdb') is None, reason='needs gdb')
def test_a_node_that_hangs_has_its_native_stacks_written_before_it_is_killed(capsys):
    # a node stuck in the middleware shows only its Python call into it: gdb names the lock
    output = io.StringIO()
    group = ProcessGroup(dict(os.environ), output=output)
    hang = ('import signal, time; signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); '
            "signal.signal(signal.SIGINT, signal.SIG_IGN); print('stuck', flush=True); "
            'time.sleep(60)')
    group.start('stuck', [sys.executable, '-c', hang])
    assert wait_until(lambda: 'stuck' in ''.join(group.last_lines['stuck']), 20.0)
    assert group.stop(grace_s=0.5)['stuck'] < 0
    relayed = output.getvalue()
    assert '[stuck] native stacks (gdb):' in relayed
    # the sleeping main thread, down to the interpreter's entry
    assert re.search(r'^\[stuck\] #0 .*(sleep|select|poll)', relayed, re.MULTILINE), relayed
    assert re.search(r'^\[stuck\] #\d+ .*Py_\w*Main', relayed, re.MULTILINE), relayed


def test_the_group_stops_its_children_one_at_a_time_the_last_started_first(capsys):
    # Fast DDS busy-waits when a participant is deleted while others leave (ProcessGroup.stop).
    output = io.StringIO()
    group = ProcessGroup(dict(os.environ), output=output)
    child = ('import signal, sys, time; name = sys.argv[1]; stopped = []; '
             'signal.signal(signal.SIGINT, lambda *_: stopped.append(1)); '
             'signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); '
             "print('ready', flush=True)\n"
             'while not stopped: time.sleep(0.01)\n'
             "print('stopping', name, flush=True); time.sleep(0.3)\n"
             "print('gone', name, flush=True)")
    for name in ('first', 'second', 'third'):
        group.start(name, [sys.executable, '-c', child, name])
    assert wait_until(lambda: all('ready' in group.last_lines[n] for n in group.processes), 20.0)
    assert group.stop(grace_s=5.0) == {'first': 0, 'second': 0, 'third': 0}
    events = [line.split('] ', 1)[1] for line in output.getvalue().splitlines()
              if 'stopping' in line or 'gone' in line]
    assert events == ['stopping third', 'gone third', 'stopping second', 'gone second',
                      'stopping first', 'gone first']
