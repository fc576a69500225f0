"""``inflarm-estimate-bag``: the tip load and pose estimated offline from a recorded bag.

Usage::

    inflarm-estimate-bag BAG --out estimates.csv [--topic joint_states] [--stiffness 172.71]
                         [--link-length 0.6] [--spring-offset 0.03]

Reads every sensor_msgs/JointState on ``--topic`` of the rosbag2 bag BAG (sqlite3 or MCAP, as
``bag_recorder`` writes), takes the positions and efforts of joint_1..joint_3 by name and
estimates the samples in the order of their time stamps with one ``LoadTracker`` (Fig. 5 of
000_ce37cf035a0a87c6, following the branch of solutions continuous in time), writing one CSV
row per sample:

    time_s, force_x_n, force_y_n, force_z_n, q_k1_rad .. q_k4_rad, tip_x_m, tip_y_m, tip_z_m,
    converged

Sign: ``effort`` is the torque each motor applies (the ros2_control convention of
``joint_states``), and the estimator takes the paper's tau_m of eq. (6), the torque the load
exerts about the motor axis: the tool uses ``tau_m = -effort``.

``time_s`` is the sample's header stamp (the bag's record time when the stamp is zero); the
estimates are NaN where ``converged`` is 0 (no estimate, or several loads fit the torques).
Samples without the three joints, or with non-finite values, are skipped and counted. Prints a
summary (samples, converged, mean force). Exit status: 0 on success, 1 on an unreadable bag or
no usable sample, 2 on bad arguments.
"""

import argparse
from collections.abc import Sequence
import csv
import math
import sys

import numpy as np

from inflarm_estimation.elastostatic import LoadTracker
from inflarm_hw.bag import bag_info, deserialize, normalize_topic, read_messages
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS
from inflarm_model.urdf import DEFAULT_LINK_LENGTH, DEFAULT_SPRING_OFFSET
from inflarm_msgs_json.cli import positive_float, run_command

PROG = 'inflarm-estimate-bag'
JOINT_STATE = 'sensor_msgs/msg/JointState'
CSV_HEADER = ('time_s', 'force_x_n', 'force_y_n', 'force_z_n', 'q_k1_rad', 'q_k2_rad',
              'q_k3_rad', 'q_k4_rad', 'tip_x_m', 'tip_y_m', 'tip_z_m', 'converged')


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-estimate-bag``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Estimate the tip load and the link deflections of the '
                               'inflatable arm from the joint states recorded in a bag.',
        epilog='effort is read as the torque each motor applies (ros2_control): the load '
               'torque of eq. (6) is taken as tau_m = -effort.')
    parser.add_argument('bag', help='rosbag2 directory (sqlite3 or MCAP)')
    parser.add_argument('--out', required=True, metavar='CSV', help='CSV file to write')
    parser.add_argument('--topic', default='joint_states',
                        help='sensor_msgs/JointState topic (default: %(default)s)')
    parser.add_argument('--stiffness', type=positive_float, nargs='+', default=[MEAN_STIFFNESS],
                        metavar='K', help='spring stiffness [N m/rad], one for all four springs '
                                          'or four values (default: %(default)s)')
    parser.add_argument('--link-length', type=positive_float, default=DEFAULT_LINK_LENGTH,
                        help='inflatable link length L [m] (default: %(default)s)')
    parser.add_argument('--spring-offset', type=positive_float, default=DEFAULT_SPRING_OFFSET,
                        help='virtual spring offset l1 [m] (default: %(default)s)')
    return parser


def read_motor_samples(bag: str, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Times [s], motor angles (N, 3) [rad] and load torques tau_m = -effort (N, 3) [N·m] on
    ``topic``, in time order, and the number of samples skipped for missing joints or
    non-finite values.

    Raises
    ------
    ValueError
        When the bag is unreadable, or ``topic`` is not in it or not a JointState topic.
    """
    name = normalize_topic(topic)
    info = bag_info(bag)
    if name in info.topics and info.topics[name].msgtype != JOINT_STATE:
        raise ValueError(f'{name} holds {info.topics[name].msgtype}, expected {JOINT_STATE}')
    names = FlexibleArm.MOTOR_JOINT_NAMES
    times, q_m, tau_m = [], [], []
    skipped = 0
    for message in read_messages(bag, [name]):
        msg = deserialize(message.data, message.msgtype)
        index = {joint: i for i, joint in enumerate(msg.name)}
        if (any(joint not in index for joint in names) or len(msg.position) != len(msg.name)
                or len(msg.effort) != len(msg.name)):
            skipped += 1
            continue
        q = [msg.position[index[joint]] for joint in names]
        # effort is the torque each motor applies (ros2_control); tau_m of eq. 6 is its negative
        tau = [-msg.effort[index[joint]] for joint in names]
        if not (np.isfinite(q).all() and np.isfinite(tau).all()):
            skipped += 1
            continue
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        times.append((stamp or message.timestamp_ns) * 1e-9)
        q_m.append(q)
        tau_m.append(tau)
    order = np.argsort(times, kind='stable')
    return (np.array(times)[order], np.array(q_m, dtype=float).reshape(-1, 3)[order],
            np.array(tau_m, dtype=float).reshape(-1, 3)[order], skipped)


def write_estimates_csv(path: str, times: np.ndarray, estimates) -> None:
    """One row per sample: time, force, q_k, tip, converged (1 or 0)."""
    with open(path, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_HEADER)
        for t, estimate in zip(times, estimates, strict=True):
            values = [*estimate.force, *estimate.q_k, *estimate.tip_position]
            writer.writerow([f'{t:.9f}', *(repr(float(v)) for v in values),
                             int(estimate.converged)])


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; returns the exit status (0 ok, 1 bad bag or no samples, 2 bad arguments)."""
    return run_command(build_parser(), argv, _estimate, errors=(OSError, ValueError),
                       error_status=1)


def _estimate(args: argparse.Namespace) -> int:
    if len(args.stiffness) not in (1, 4):
        raise argparse.ArgumentError(
            None, f'--stiffness takes 1 or 4 values, got {len(args.stiffness)}')
    stiffness = args.stiffness[0] if len(args.stiffness) == 1 else args.stiffness
    arm = FlexibleArm(args.link_length, args.spring_offset)
    times, q_m, tau_m, skipped = read_motor_samples(args.bag, args.topic)
    if len(times) == 0:
        raise ValueError(f'no {args.topic} sample with positions and efforts of '
                         f'{list(FlexibleArm.MOTOR_JOINT_NAMES)} in {args.bag} '
                         f'({skipped} skipped)')
    tracker = LoadTracker(arm, stiffness)
    estimates = [tracker.update(q, tau) for q, tau in zip(q_m, tau_m, strict=True)]
    write_estimates_csv(args.out, times, estimates)
    forces = [e.force for e in estimates if e.converged]
    converged = len(forces)
    mean = np.mean(forces, axis=0) if converged else np.full(3, math.nan)
    print(f'{len(times)} samples ({skipped} skipped), {converged} converged; mean force '
          f'[{mean[0]:.3f}, {mean[1]:.3f}, {mean[2]:.3f}] N; wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
