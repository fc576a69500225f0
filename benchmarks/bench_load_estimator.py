"""Does ``load_estimator`` keep up with joint_states at 1 kHz? (issue 9: 20 s, no drop).

Run as ``source scripts/env.sh && python benchmarks/bench_load_estimator.py [--rate 1000]
[--seconds 20]``. The node runs as its own process, as the launcher starts it; this process
publisher (a process of its own) sends joint_states (reliable, as joint_state_broadcaster) of a
smooth motion under a load ramping from 10 to 60 N, at ``--rate``; this process reads the
node's diagnostics: the samples it processed (``samples_total``), its converged estimates, and
the samples DDS lost before it (``lost_samples_total``). A drop is a published sample the node
never processed; the target is none (the command exits 1 otherwise). The domain is
``ROS_DOMAIN_ID``, 101 unless set.
"""

import argparse
import multiprocessing
import os
import sys
import time

from common import Row, Target, print_rows
import numpy as np

from inflarm_bringup.processes import NodeProcess, ros_environment, start_node_process

os.environ.update(ros_environment())
# Outside 1-100, the domains the tests take under a lock (tests/conftest.py).
os.environ.setdefault('ROS_DOMAIN_ID', '101')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from inflarm_model.elastostatics import motor_torques, spring_deflections  # noqa: E402
from inflarm_model.kinematics import FlexibleArm  # noqa: E402
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS  # noqa: E402


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


def publish(rate: float, n: int, ready, done) -> None:
    """Publish n samples of `motion` at ``rate`` (in a process of its own, so that nothing else
    in the benchmark competes with it for the interpreter)."""
    q_m, effort = motion(n)
    rclpy.init()
    node = rclpy.create_node('bench_joint_states')
    publisher = node.create_publisher(JointState, 'joint_states', JOINT_STATE_QOS)
    while publisher.get_subscription_count() == 0:
        time.sleep(0.05)
    ready.set()
    time.sleep(1.0)  # the estimator's publishers are discovered too
    msg = JointState(name=list(FlexibleArm.MOTOR_JOINT_NAMES))
    period, start = 1.0 / rate, time.monotonic()
    for i in range(n):
        # Each sample is due at its own time: an oversleep is caught up on, the mean rate kept.
        delay = start + i * period - time.monotonic()
        if delay > 0.0:
            time.sleep(delay)
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1 + i // 10**6, (i % 10**6) * 1000
        msg.position, msg.effort = q_m[i].tolist(), effort[i].tolist()
        publisher.publish(msg)
    done.value = time.monotonic() - start
    time.sleep(1.0)  # let the last samples be acknowledged
    node.destroy_node()
    rclpy.try_shutdown()


def measure(rate: float, seconds: float) -> dict:
    """Run the node, publish ``rate * seconds`` samples, and return its diagnostics' totals."""
    n = int(rate * seconds)
    estimator = start_node_process(NodeProcess('inflarm_estimation', 'load_estimator').command(),
                                   dict(os.environ))
    spawn = multiprocessing.get_context('spawn')
    ready, done = spawn.Event(), spawn.Value('d', 0.0)
    publisher = spawn.Process(target=publish, args=(rate, n, ready, done))
    try:
        publisher.start()
        rclpy.init()
        node = rclpy.create_node('bench_load_estimator')
        totals = {'samples_total': 0, 'lost_samples_total': 0, 'cold_starts_total': 0}
        converged = [0]

        def on_diagnostics(msg: DiagnosticArray) -> None:
            values = {kv.key: kv.value for kv in msg.status[0].values}
            for key in totals:
                totals[key] = int(values.get(key, 0))
            converged[0] += int(values.get('converged', 0))
        node.create_subscription(DiagnosticArray, 'diagnostics', on_diagnostics, RELIABLE_QOS)
        executor = SingleThreadedExecutor()
        executor.add_node(node)

        def spin_until(predicate, timeout_s: float) -> bool:
            deadline = time.monotonic() + timeout_s
            while not predicate():
                if time.monotonic() > deadline:
                    return False
                executor.spin_once(timeout_sec=0.1)
            return True

        if not spin_until(ready.is_set, 30.0):
            raise RuntimeError('load_estimator never subscribed to joint_states within 30 s')
        spin_until(lambda: not publisher.is_alive(), seconds + 30.0)
        progress = [-1, time.monotonic()]

        def settled() -> bool:
            """All samples processed, or no progress over 1.5 diagnostics periods (1 s)."""
            if totals['samples_total'] >= n:
                return True
            if totals['samples_total'] != progress[0]:
                progress[:] = [totals['samples_total'], time.monotonic()]
            return time.monotonic() - progress[1] > 1.5

        spin_until(settled, 10.0)
        estimator.send_signal(2)
        code = estimator.wait(timeout=10.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    finally:  # stopped above; killed here if something failed first
        if estimator.poll() is None:
            estimator.kill()
        if publisher.is_alive():
            publisher.kill()
    return {'rate': rate, 'seconds': seconds, 'published': n, 'published_in_s': done.value,
            'processed': totals['samples_total'], 'lost': totals['lost_samples_total'],
            'converged': converged[0], 'cold_starts': totals['cold_starts_total'],
            'exit_code': code}


def rows(m: dict) -> list[Row]:
    """The summary row: samples processed against samples published (target: all)."""
    return [Row(f"joint_states processed at {m['rate']:.0f} Hz for {m['seconds']:g} s",
                m['processed'], '', 'samples published', m['published'],
                Target(at_least=m['published']),
                f"{m['lost']} lost in transport, {m['converged']} converged, "
                f"{m['cold_starts']} cold start(s), node exit code {m['exit_code']}")]


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: 1 s at 1 kHz, about 10 s in all; full: 20 s, about
    30 s)."""
    return rows(measure(1000.0, 1.0 if quick else 20.0))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='joint_states rate [Hz]')
    parser.add_argument('--seconds', type=float, default=20.0, help='how long to publish [s]')
    args = parser.parse_args(argv)
    m = measure(args.rate, args.seconds)
    n, processed = m['published'], m['processed']
    print(f"load_estimator at {args.rate:.0f} Hz for {args.seconds:.0f} s "
          f"(published in {m['published_in_s']:.2f} s):")
    print(f'  published            {n}')
    print(f'  processed            {processed}   dropped {n - processed} '
          f'({100.0 * (n - processed) / n:.2f} %)')
    print(f"  lost in transport    {m['lost']} (DDS message_lost events)")
    print(f"  converged estimates  {m['converged']}   cold starts {m['cold_starts']}")
    print(f"  exit code            {m['exit_code']}")
    print()
    print_rows('load_estimator', rows(m))
    return 0 if processed == n and m['exit_code'] == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
