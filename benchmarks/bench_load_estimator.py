"""Does ``load_estimator`` keep up with joint_states at 500 Hz, 1 kHz and 2 kHz? (issue 19).

Run as ``source scripts/env.sh && python benchmarks/bench_load_estimator.py [--seconds 20]``.
Every configuration is a run of its own in the same benchmark, on the same machine:

- the floor: a bare rclpy node (its own process, ``SingleThreadedExecutor`` through the shared
  spin helper) that receives ``JointState`` and publishes one ``WrenchStamped`` per sample, at
  1 kHz;
- ``load_estimator`` (its own process, as the launcher starts it: real-time priority 50 where
  the user may take it) at 1 kHz on each executor (``INFLARM_EXECUTOR``: ``single_threaded``,
  ``events``), then on the default executor at 500 Hz and 2 kHz, and at 1 kHz with two busy
  processes (a Python loop each) beside it, at its default priority and at normal priority
  (``INFLARM_REALTIME_PRIORITY=0``); the floor at normal priority.

A publisher (a process of its own) sends joint_states (reliable, as joint_state_broadcaster) of a
smooth motion under a load ramping from 10 to 60 N, each stamped with the wall clock when it is
sent. Figures of a run: the samples the node estimated (its diagnostics: converged estimates
against samples published), its CPU share while the publisher runs (utime + stime from /proc,
% of one core), and the latency from a sample's stamp to the receipt of its
``estimated_wrench`` here (p50, p99; this process receives them raw, without deserializing, so
its own share of the latency is small but included; it runs at the node's priority, as a
controller consuming the estimates would). The domain is ``ROS_DOMAIN_ID``, 101
unless set. The machine is shared: compare ratios to the floor more than absolute numbers.
"""

import argparse
import multiprocessing
import os
import signal
import struct
import sys
import time

from common import Row, Target, print_rows
import numpy as np

from inflarm_bringup.processes import NodeProcess, ros_environment, start_node_process

os.environ.update(ros_environment())
# Outside 1-100, the domains the tests take under a lock (tests/conftest.py).
os.environ.setdefault('ROS_DOMAIN_ID', '101')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from inflarm_estimation.nodes.load_estimator import (  # noqa: E402
    JOINT_STATE_INPUT_QOS,
    REALTIME_PRIORITY,
)
from inflarm_model.elastostatics import motor_torques, spring_deflections  # noqa: E402
from inflarm_model.kinematics import FlexibleArm  # noqa: E402
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS  # noqa: E402
from inflarm_msgs_json.ros.spin import (  # noqa: E402
    REALTIME_PRIORITY_ENV,
    spin_node,
    take_realtime_priority,
)

ESTIMATED_TARGET = 99.5  # % of samples estimated at 1 kHz on a quiet machine
ESTIMATED_BUSY_TARGET = 95.0  # ... with two busy processes beside it
CPU_RATIO_TARGET = 1.5  # CPU share / the floor's
LATENCY_P99_TARGET_MS = 5.0
WRENCH_QOS = RELIABLE_QOS.__class__(depth=1000, reliability=RELIABLE_QOS.reliability,
                                    history=RELIABLE_QOS.history)


def motion(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Motor angles and the efforts (torques the motors apply) of a smooth loaded motion."""
    arm = FlexibleArm()
    t = np.linspace(0.0, 1.0, n)
    q_m = np.stack([0.3 * np.sin(2 * np.pi * t), 0.6 + 0.2 * np.sin(4 * np.pi * t),
                    -1.2 + 0.3 * np.cos(2 * np.pi * t)], axis=1)
    force = np.outer(10.0 + 50.0 * t, [0.0, 0.6, -0.8])
    q_k = spring_deflections(arm, q_m, force, 172.71).q_k
    q = np.zeros((n, 7))
    q[:, list(FlexibleArm.MOTOR_INDICES)], q[:, list(FlexibleArm.SPRING_INDICES)] = q_m, q_k
    return q_m, -motor_torques(arm, q, force)


def publish(rate: float, n: int, ready, started, done) -> None:
    """Publish n samples of `motion` at ``rate``, stamped with the wall clock (in a process of
    its own, so that nothing else in the benchmark competes with it for the interpreter)."""
    q_m, effort = motion(n)
    rclpy.init()
    node = rclpy.create_node('bench_joint_states')
    publisher = node.create_publisher(JointState, 'joint_states', JOINT_STATE_QOS)
    while publisher.get_subscription_count() == 0:
        time.sleep(0.05)
    ready.set()
    time.sleep(1.5)  # the node's publishers are discovered too
    msg = JointState(name=list(FlexibleArm.MOTOR_JOINT_NAMES))
    period, start = 1.0 / rate, time.monotonic()
    started.set()
    for i in range(n):
        # Each sample is due at its own time: an oversleep is caught up on, the mean rate kept.
        delay = start + i * period - time.monotonic()
        if delay > 0.0:
            time.sleep(delay)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
        msg.position, msg.effort = q_m[i].tolist(), effort[i].tolist()
        publisher.publish(msg)
    done.value = time.monotonic() - start
    time.sleep(1.0)  # let the last samples be acknowledged
    node.destroy_node()
    rclpy.try_shutdown()


class PassThrough(Node):
    """The floor: receives JointState and publishes one WrenchStamped (its stamp) per sample,
    and the estimator's diagnostics keys (samples_total) for the same bookkeeping."""

    def __init__(self) -> None:
        super().__init__('bench_pass_through')
        self.publisher = self.create_publisher(WrenchStamped, 'estimated_wrench', RELIABLE_QOS)
        self.diagnostics = self.create_publisher(DiagnosticArray, 'diagnostics', RELIABLE_QOS)
        self.out = WrenchStamped()
        self.count = 0
        self.create_subscription(JointState, 'joint_states', self.on_joint_states,
                                 JOINT_STATE_INPUT_QOS)
        self.create_timer(0.5, self.report)

    def on_joint_states(self, msg: JointState) -> None:
        self.out.header.stamp = msg.header.stamp
        self.publisher.publish(self.out)
        self.count += 1

    def report(self) -> None:
        self.diagnostics.publish(DiagnosticArray(status=[DiagnosticStatus(values=[
            KeyValue(key='samples_total', value=str(self.count)),
            KeyValue(key='converged_total', value=str(self.count))])]))


def pass_through() -> None:
    """Run `PassThrough` on a SingleThreadedExecutor (the shared spin helper) until SIGINT."""
    os.environ['INFLARM_EXECUTOR'] = 'single_threaded'
    spin_node(PassThrough, ['--ros-args', '--log-level', 'WARN'])


def busy() -> None:
    """A busy process: a Python loop, until killed."""
    while True:
        pass


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process [s]."""
    with open(f'/proc/{pid}/stat') as stat:
        fields = stat.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def measure(rate: float, seconds: float, executor: str = 'events', floor: bool = False,
            busy_processes: int = 0, priority: int | None = None) -> dict:
    """One run: start the node (the floor or load_estimator on ``executor``, at its default
    scheduling or the real-time ``priority``, 0 for none), publish ``rate * seconds`` samples,
    and return what it estimated, its CPU share and the latency (received here at the node's
    priority, as a controller consuming the estimates would run)."""
    n = int(rate * seconds)
    spawn = multiprocessing.get_context('spawn')
    env = dict(os.environ, INFLARM_EXECUTOR=executor)
    env.pop(REALTIME_PRIORITY_ENV, None)
    if priority is not None:
        env[REALTIME_PRIORITY_ENV] = str(priority)
    receiver_priority = priority if priority is not None else 0 if floor else REALTIME_PRIORITY
    command = ([sys.executable, os.path.abspath(__file__), '--pass-through'] if floor
               else NodeProcess('inflarm_estimation', 'load_estimator').command())
    node_process = start_node_process(command, env)
    pid = node_process.pid
    hogs = [spawn.Process(target=busy, daemon=True) for _ in range(busy_processes)]
    for hog in hogs:
        hog.start()
    ready, started, done = spawn.Event(), spawn.Event(), spawn.Value('d', 0.0)
    publisher = spawn.Process(target=publish, args=(rate, n, ready, started, done))
    latencies: list[int] = []
    totals = {'samples_total': 0, 'cold_starts_total': 0}
    converged = [0]
    try:
        publisher.start()
        rclpy.init()
        node = rclpy.create_node('bench_load_estimator')

        def on_diagnostics(msg: DiagnosticArray) -> None:
            values = {kv.key: kv.value for kv in msg.status[0].values}
            for key in totals:
                totals[key] = int(values.get(key, totals[key]))
            if 'converged_total' in values:  # the floor
                converged[0] = int(values['converged_total'])
            else:
                converged[0] += int(values.get('converged', 0))

        def on_wrench(data: bytes) -> None:  # CDR: 4 bytes of encapsulation, then the stamp
            sec, nanosec = struct.unpack_from('<iI', data, 4)
            latencies.append(time.time_ns() - sec * 10**9 - nanosec)

        node.create_subscription(DiagnosticArray, 'diagnostics', on_diagnostics, RELIABLE_QOS)
        node.create_subscription(WrenchStamped, 'estimated_wrench', on_wrench, WRENCH_QOS,
                                 raw=True)
        spinner = SingleThreadedExecutor()
        spinner.add_node(node)
        # after the publisher and busy processes started: they must not inherit it
        if receiver_priority and (problem := take_realtime_priority(receiver_priority)):
            print(f'bench: the receiver runs at normal priority: {problem}', file=sys.stderr)

        def spin_until(predicate, timeout_s: float) -> bool:
            deadline = time.monotonic() + timeout_s
            while not predicate():
                if time.monotonic() > deadline:
                    return False
                spinner.spin_once(timeout_sec=0.05)
            return True

        if not spin_until(ready.is_set, 30.0):
            raise RuntimeError('the node never subscribed to joint_states within 30 s')
        spin_until(started.is_set, 10.0)
        latencies.clear()
        cpu_start, wall_start = cpu_seconds(pid), time.monotonic()
        spin_until(lambda: done.value > 0.0, seconds + 30.0)
        cpu = (cpu_seconds(pid) - cpu_start) / (time.monotonic() - wall_start)
        progress = [-1, time.monotonic()]

        def settled() -> bool:
            """All samples processed, or no progress over 1.5 diagnostics periods (1.5 s)."""
            if totals['samples_total'] >= n:
                return True
            if totals['samples_total'] != progress[0]:
                progress[:] = [totals['samples_total'], time.monotonic()]
            return time.monotonic() - progress[1] > 1.5

        spin_until(settled, 10.0)
        spin_until(lambda: False, 1.2)  # the last diagnostics report
        node_process.send_signal(signal.SIGINT)
        code = node_process.wait(timeout=10.0)
        spinner.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    finally:  # stopped above; killed here if something failed first
        take_realtime_priority(0)  # the next run's processes start at normal priority
        for process in [publisher, *hogs]:
            if process.is_alive():
                process.kill()
        if node_process.poll() is None:
            node_process.kill()
    lat = np.array(latencies) / 1e6 if latencies else np.array([np.nan])
    return {'rate': rate, 'seconds': seconds, 'executor': 'single_threaded' if floor
            else executor, 'floor': floor, 'busy': busy_processes, 'published': n,
            'priority': priority, 'published_in_s': done.value,
            'processed': totals['samples_total'],
            'estimated': converged[0],
            'lost': n - totals['samples_total'],  # published, never reached the node
            'cold_starts': totals['cold_starts_total'], 'cpu': 100.0 * cpu,
            'received': len(latencies), 'p50_ms': float(np.percentile(lat, 50)),
            'p99_ms': float(np.percentile(lat, 99)), 'exit_code': code}


CONFIGURATIONS = (  # (name, measure's keyword arguments): the floor first
    ('floor', dict(rate=1000.0, floor=True)),
    ('1 kHz, single_threaded', dict(rate=1000.0, executor='single_threaded')),
    ('1 kHz, events', dict(rate=1000.0, executor='events')),
    ('500 Hz, events', dict(rate=500.0, executor='events')),
    ('2 kHz, events', dict(rate=2000.0, executor='events')),
    ('1 kHz, events, 2 busy processes', dict(rate=1000.0, executor='events', busy_processes=2)),
    # the same at normal priority: what the real-time default is for
    ('1 kHz, events, 2 busy processes, normal priority',
     dict(rate=1000.0, executor='events', busy_processes=2, priority=0)),
    # what any rclpy node keeps up with under that load: the busy target's baseline
    ('floor, 2 busy processes', dict(rate=1000.0, floor=True, busy_processes=2)),
)


QUICK = ('floor', '1 kHz, events')  # --quick: the floor and the default at 1 kHz only


def measure_all(seconds: float, names: tuple[str, ...] | None = None) -> dict[str, dict]:
    """Every run of `CONFIGURATIONS` (or those ``names``), one after another."""
    return {name: measure(seconds=seconds, **kwargs) for name, kwargs in CONFIGURATIONS
            if names is None or name in names}


def rows(runs: dict[str, dict]) -> list[Row]:
    """Summary rows: per run, % estimated, CPU against the floor's, latency p50/p99."""
    floor = runs['floor']
    out = [Row('pass-through floor at 1 kHz (SingleThreadedExecutor): samples answered',
               100.0 * floor['estimated'] / floor['published'], '%',
               note=f"CPU {floor['cpu']:.0f}% of a core, latency p50 {floor['p50_ms']:.2f} ms "
                    f"p99 {floor['p99_ms']:.2f} ms, {floor['seconds']:g} s")]
    for name, m in runs.items():
        if m['floor']:
            if name != 'floor':
                out.append(Row(f'pass-through {name}: samples answered',
                               100.0 * m['estimated'] / m['published'], '%',
                               note=f"{m['lost']} lost in transport, CPU {m['cpu']:.0f}% of a "
                                    f"core, latency p99 {m['p99_ms']:.2f} ms"))
            continue
        label = f'load_estimator {name}'
        target = ESTIMATED_BUSY_TARGET if m['busy'] else ESTIMATED_TARGET
        targeted = m['rate'] == 1000.0 and m['priority'] is None  # the node as it ships
        context = (f"{m['estimated']} of {m['published']} estimated, {m['processed']} processed,"
                   f" {m['lost']} lost in transport, {m['cold_starts']} cold start(s), "
                   f"exit code {m['exit_code']}, {m['seconds']:g} s")
        out += [
            Row(f'{label}: samples estimated', 100.0 * m['estimated'] / m['published'], '%',
                target=Target(at_least=target) if targeted else None, note=context),
            Row(f'{label}: CPU', m['cpu'], '%', 'the floor at 1 kHz', floor['cpu'],
                Target(ratio_at_most=CPU_RATIO_TARGET) if targeted else None,
                '% of one core while the publisher runs'),
            Row(f'{label}: latency p50', m['p50_ms'], 'ms', 'the floor', floor['p50_ms'],
                note='stamp to estimated_wrench received'),
            Row(f'{label}: latency p99', m['p99_ms'], 'ms', 'the floor', floor['p99_ms'],
                Target(at_most=LATENCY_P99_TARGET_MS) if m['priority'] is None else None,
                f"{m['received']} wrenches received"),
        ]
    return out


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: the floor and 1 kHz on the default executor, 1 s
    each, about 20 s in all; full: every run, 20 s each, about 3 min)."""
    return rows(measure_all(1.0, QUICK) if quick else measure_all(20.0))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=20.0, help='how long a run publishes')
    parser.add_argument('--pass-through', action='store_true',
                        help='be the floor node (the benchmark starts it so)')
    args = parser.parse_args(argv)
    if args.pass_through:
        pass_through()
        return 0
    runs = measure_all(args.seconds)
    print(f'{"run":36s} {"published":>9s} {"estimated":>9s} {"%":>7s} {"CPU %":>6s} '
          f'{"p50 ms":>7s} {"p99 ms":>7s}')
    for name, m in runs.items():
        print(f"{name:36s} {m['published']:9d} {m['estimated']:9d} "
              f"{100.0 * m['estimated'] / m['published']:7.2f} {m['cpu']:6.1f} "
              f"{m['p50_ms']:7.2f} {m['p99_ms']:7.2f}")
    print()
    print_rows('load_estimator', rows(runs))
    return 0


if __name__ == '__main__':
    # Run as the module, not as __main__: the spawned publisher and busy processes then find
    # their functions by an importable name.
    import bench_load_estimator  # noqa: PLW0406 (itself, importable: benchmarks/ is on the path)

    sys.exit(bench_load_estimator.main())
