"""Every node executable stops cleanly whenever SIGINT or SIGTERM comes: during imports, during
construction, inside a callback, while it closes a bag.

Each installed node executable is started as a real process (as the launcher starts it: stop
signals blocked until the node owns them) and interrupted at a seeded random moment 0-3 s after
start, several times per executable, SIGINT and SIGTERM alternately. Every run must exit with
code 0 within MAX_EXIT_S of the signal, without a traceback.
"""

from concurrent.futures import ThreadPoolExecutor
import os
import pathlib
import random
import re
import signal
import subprocess
import time

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
import rclpy

from inflarm_bringup.processes import NodeProcess, ros_environment, start_node_process
from inflarm_hw.bag import BagWriter, bag_info, serialize, typestore
from inflarm_model.elastostatics import motor_torques, spring_deflections
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS
from inflarm_msgs_json.ros.qos import RELIABLE_QOS
from ros_harness import spin_until, wait_until

pytestmark = pytest.mark.system
REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())
NODE_ENTRY = re.compile(r"'(\w+) = (inflarm_\w+)\.executables:(\w+)'")
RUNS_PER_EXECUTABLE = 6
MAX_DELAY_S = 3.0
# The slowest of 108 stops, measured: 2.14 s beside one CPU hog and other jobs (load average
# 3-4 on the 2 cores); beside three CPU hogs (load average 15), 3.66 s (robot_description,
# SIGTERM 2.2 s after start: still starting), the other 107 0.8-1.0 s; the issue saw 3.3-3.5 s
# at load 6. A hang waits 30 s.
MAX_EXIT_S = 6.0
SEED = 20261201
LOAD = np.array([0.0, 10.0, -15.0])


def node_executables() -> list[tuple[str, str]]:
    """(package, executable) of every node executable declared in the setup.py files."""
    found = []
    for package in PACKAGES:
        text = (REPO_ROOT / package / 'setup.py').read_text()
        found += [(package, exe) for exe, _, _ in NODE_ENTRY.findall(text)]
    return found


def extra_arguments(executable: str, workdir: pathlib.Path, run: int) -> list[str]:
    """Parameters an executable cannot start without."""
    if executable == 'bag_recorder':
        return ['-p', 'topics:=[joint_states, robot_description]',
                '-p', f'output:={workdir / f"recorded_{run}"}']
    if executable == 'bag_player':
        return ['-p', f'input:={workdir / "replay"}', '-p', 'start_delay_s:=0.0',
                '-p', 'loop:=true', '-p', 'rate:=50.0']
    return []


def write_replay_bag(path: pathlib.Path) -> None:
    """200 joint states 10 ms apart of the arm holding its default load (valid samples)."""
    types = typestore().types
    arm = FlexibleArm()
    with BagWriter(path) as bag:
        bag.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        for i in range(200):
            q_m = np.array([0.2, 0.5 + 0.001 * i, -1.1])
            q_k = spring_deflections(arm, q_m, LOAD, MEAN_STIFFNESS).q_k
            tau_m = motor_torques(arm, FlexibleArm.assemble_q(q_m, q_k), LOAD)
            msg = types['sensor_msgs/msg/JointState'](
                header=types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=1, nanosec=i), frame_id=''),
                name=list(FlexibleArm.MOTOR_JOINT_NAMES), position=q_m, velocity=np.zeros(3),
                effort=-tau_m)
            bag.write('/joint_states', i * 10_000_000,
                      serialize(msg, 'sensor_msgs/msg/JointState'))


def interrupt_once(package: str, executable: str, delay_s: float, signum: int,
                   env: dict[str, str], workdir: pathlib.Path, run: int) -> dict:
    command = NodeProcess(package, executable).command() + extra_arguments(executable, workdir,
                                                                           run)
    process = start_node_process(command, env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True)
    time.sleep(delay_s)
    process.send_signal(signum)
    sent = time.monotonic()
    try:
        output, _ = process.communicate(timeout=30.0)
        exit_s = time.monotonic() - sent
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
        exit_s = float('inf')
    return dict(executable=executable, delay_s=delay_s, signal=signal.Signals(signum).name,
                code=process.returncode, exit_s=exit_s, output=output)


def test_every_node_exits_cleanly_whenever_it_is_interrupted(tmp_path, domain_id):
    executables = node_executables()
    assert len(executables) >= 12, executables
    write_replay_bag(tmp_path / 'replay')
    env = ros_environment(dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
                               ROS_LOG_DIR=str(tmp_path / 'ros_log')))
    rng = random.Random(SEED)
    runs = [(package, executable, rng.uniform(0.0, MAX_DELAY_S),
             (signal.SIGINT, signal.SIGTERM)[i % 2], i)
            for package, executable in executables for i in range(RUNS_PER_EXECUTABLE)]
    rng.shuffle(runs)
    # Two at a time, one per core of the CI machine: with three on its two cores, two CI runs
    # each had one stop of 96 take longer (2.2 s, 3.7 s; exit code 0).
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(
            lambda r: interrupt_once(r[0], r[1], r[2], r[3], env, tmp_path, r[4]), runs))

    failures = [r for r in results
                if r['code'] != 0 or r['exit_s'] > MAX_EXIT_S or 'Traceback' in r['output']]
    slowest = max(r['exit_s'] for r in results)
    print(f'{len(results)} interrupts of {len(executables)} executables; slowest exit '
          f'{slowest:.2f} s; failures {len(failures)}')
    assert not failures, '\n\n'.join(
        f"{r['executable']}: {r['signal']} at {r['delay_s']:.2f} s -> code {r['code']} after "
        f"{r['exit_s']:.2f} s\n{r['output'][-3000:]}" for r in failures[:5])


def test_nodes_busy_with_1_khz_joint_states_exit_cleanly_on_sigterm(node_processes, executor,
                                                                      tmp_path):
    """The estimator estimating and the recorder writing, at 1 kHz, stopped mid-stream."""
    write_replay_bag(tmp_path / 'replay')
    node_processes.start('inflarm_hw', 'bag_player', parameters={
        'input': str(tmp_path / 'replay'), 'loop': True, 'rate': 10.0, 'start_delay_s': 0.0})
    probe = rclpy.create_node('probe', context=executor.context)
    wrenches = []
    probe.create_subscription(WrenchStamped, 'estimated_wrench', wrenches.append, RELIABLE_QOS)
    executor.add_node(probe)
    for run in range(3):
        estimator = node_processes.start('inflarm_estimation', 'load_estimator',
                                         name=f'load_estimator_{run}')
        recorder = node_processes.start(
            'inflarm_hw', 'bag_recorder', name=f'bag_recorder_{run}', parameters={
                'topics': ['joint_states', 'estimated_wrench'],
                'output': str(tmp_path / f'busy_{run}')})
        recording = node_processes.output().count('recording /estimated_wrench') + 1
        assert wait_until(lambda n=recording: node_processes.output().count(
            'recording /estimated_wrench') >= n, 20.0), node_processes.output()
        busy = len(wrenches) + 50
        assert spin_until(executor, lambda n=busy: len(wrenches) >= n), node_processes.output()
        estimator.send_signal(signal.SIGTERM)
        recorder.send_signal(signal.SIGINT if run % 2 else signal.SIGTERM)
        assert estimator.wait(timeout=MAX_EXIT_S + 3.0) == 0, node_processes.output()
        assert recorder.wait(timeout=MAX_EXIT_S + 3.0) == 0, node_processes.output()
        assert bag_info(tmp_path / f'busy_{run}').topics['/joint_states'].message_count > 0
    assert 'Traceback' not in node_processes.output(), node_processes.output()
