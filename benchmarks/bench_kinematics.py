"""Speed of the inflatable-arm kinematics (inflarm_model.kinematics).

Run as ``python benchmarks/bench_kinematics.py`` (with inflarm_model importable, e.g.
``PYTHONPATH=inflarm_model``). Prints medians in microseconds and ratios against baselines
measured in the same run:

- one call of ``FlexibleArm.fk_and_jacobian`` against a bare Pinocchio
  ``computeFrameJacobian`` call on the same model (target: ratio <= 1.5) and against the plain
  numpy per-joint DH chain ``dh_jacobian_reference`` (one pass of 4x4 products, the pose is
  its last frame);
- the vectorized batch forms per configuration for N = 10,000 (target: <= 1 us each).

Candidates are timed round-robin, one ``timeit`` batch each per round, so that load from other
processes on the machine falls on all of them alike; the median over rounds is reported.
"""

import argparse
import statistics
import sys
import timeit

import numpy as np
import pinocchio as pin

from inflarm_model.kinematics import FlexibleArm, dh_fk_reference, dh_jacobian_reference

TARGET_SINGLE_RATIO = 1.5
TARGET_BATCH_US = 1.0


def interleaved_medians(
    candidates: dict[str, str], namespace: dict, rounds: int, min_time_s: float
) -> dict[str, float]:
    """Median time per call [us] of each statement, timed round-robin."""
    timers = {name: timeit.Timer(stmt, globals=namespace) for name, stmt in candidates.items()}
    numbers = {}
    for name, timer in timers.items():
        n, t = timer.autorange()
        numbers[name] = max(1, int(n * min_time_s / t))
    samples: dict[str, list[float]] = {name: [] for name in timers}
    for _ in range(rounds):
        for name, timer in timers.items():
            samples[name].append(timer.timeit(numbers[name]) / numbers[name] * 1e6)
    return {name: statistics.median(s) for name, s in samples.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rounds', type=int, default=31, help='round-robin rounds')
    parser.add_argument('--batch', type=int, default=10_000, help='N for the batch forms')
    args = parser.parse_args(argv)

    rng = np.random.default_rng(7)
    arm = FlexibleArm(link_length=0.6, spring_offset=0.03)
    q = rng.uniform(-np.pi, np.pi, arm.n_joints)
    Q = rng.uniform(-np.pi, np.pi, (args.batch, arm.n_joints))
    # Bare Pinocchio: same model, its own workspace, the call as a user writes it.
    model = arm.model
    data = model.createData()
    frame_id = arm.tip_frame_id
    tip = data.oMf[frame_id]  # live reference, as FlexibleArm keeps one
    namespace = {
        'arm': arm, 'q': q, 'Q': Q, 'pin': pin, 'model': model, 'data': data,
        'frame_id': frame_id, 'tip': tip, 'table': arm.dh_table,
        'dh_jacobian_reference': dh_jacobian_reference, 'dh_fk_reference': dh_fk_reference,
    }

    single = interleaved_medians(
        {
            'bare pin.computeFrameJacobian': (
                'pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL_WORLD_ALIGNED)'
            ),
            'bare J + pose, data.oMf[tip] indexed': (
                'pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL_WORLD_ALIGNED); '
                'data.oMf[frame_id].homogeneous'
            ),
            'bare J + pose, cached oMf reference': (
                'pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL_WORLD_ALIGNED); '
                'tip.homogeneous'
            ),
            'FlexibleArm.fk_and_jacobian': 'arm.fk_and_jacobian(q)',
            'FlexibleArm.fk': 'arm.fk(q)',
            'FlexibleArm.jacobian': 'arm.jacobian(q)',
            'numpy DH chain (dh_jacobian_reference)': 'dh_jacobian_reference(table, q)',
        },
        namespace, args.rounds, min_time_s=0.02,
    )
    bare = single['bare pin.computeFrameJacobian']
    print(f'single configuration, FlexibleArm (7 DOF), median of {args.rounds} rounds')
    print(f'{"call":42s} {"us/call":>9s} {"x bare J":>11s}')
    for name, t in single.items():
        print(f'{name:42s} {t:9.3f} {t / bare:11.2f}')
    ours = single['FlexibleArm.fk_and_jacobian']
    ratio = ours / bare
    verdict = 'met' if ratio <= TARGET_SINGLE_RATIO else 'NOT met'
    print(f'fk_and_jacobian / bare computeFrameJacobian = {ratio:.2f} '
          f'(target <= {TARGET_SINGLE_RATIO}: {verdict})')
    same_outputs = single['bare J + pose, cached oMf reference']
    print(f'fk_and_jacobian / bare J + pose (same outputs, unvalidated) = '
          f'{ours / same_outputs:.2f}')
    numpy_chain = single['numpy DH chain (dh_jacobian_reference)']
    print(f'numpy DH chain / fk_and_jacobian = {numpy_chain / ours:.1f}')

    batch = interleaved_medians(
        {
            'fk_batch': 'arm.fk_batch(Q)',
            'jacobian_batch': 'arm.jacobian_batch(Q)',
            'fk_and_jacobian_batch': 'arm.fk_and_jacobian_batch(Q)',
        },
        namespace, max(5, args.rounds // 3), min_time_s=0.05,
    )
    loop = single['FlexibleArm.fk_and_jacobian']
    print()
    print(f'batch, N = {args.batch}, per configuration')
    print(f'{"call":42s} {"us/config":>9s} {"x loop":>11s}')
    for name, t in batch.items():
        per_config = t / args.batch
        print(f'{name:42s} {per_config:9.3f} {per_config / loop:11.2f}')
    worst = max(batch.values()) / args.batch
    verdict = 'met' if worst <= TARGET_BATCH_US else 'NOT met'
    print(f'(x loop: against one fk_and_jacobian call per configuration; '
          f'target <= {TARGET_BATCH_US} us/config: {verdict})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
