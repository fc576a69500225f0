"""Speed of the inflatable-arm kinematics (inflarm_model.kinematics).

Run as ``source scripts/env.sh && python benchmarks/bench_kinematics.py [--rounds 31]
[--batch 10000]``. Prints medians in microseconds and ratios against baselines measured in the
same run:

- one call of ``FlexibleArm.fk_and_jacobian`` against a bare Pinocchio
  ``computeFrameJacobian`` call on the same model (no target since issue 19: no caller needs
  one call faster) and against the plain numpy per-joint DH chain ``dh_jacobian_reference``
  (one pass of 4x4 products, the pose is its last frame);
- the vectorized batch forms per configuration for N = 10,000 (target: <= 1 us each).

Candidates are timed round-robin (``common.interleaved``), so that load from other processes on
the machine falls on all of them alike; the median over rounds is reported.
"""

import argparse
import sys

from common import Row, Target, interleaved, print_rows
import numpy as np
import pinocchio as pin

from inflarm_model.kinematics import FlexibleArm, dh_fk_reference, dh_jacobian_reference

# The former target of one call, <= 1.5x bare Pinocchio, was dropped (issue 19): it serves no
# user. The loops that need speed run batches or compiled kernels (the solvers, LoadTracker's
# warm step); the nodes call fk once per message (load_estimator: ~2 us of a 1 ms period).
SINGLE_TARGET_DROPPED = ('no target: no caller needs one call faster (loops use the batch '
                         'forms or the compiled kernels)')
TARGET_BATCH_US = 1.0
BARE = 'bare pin.computeFrameJacobian'
SINGLE = {
    BARE: 'pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL_WORLD_ALIGNED)',
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
}
BATCH = {
    'fk_batch': 'arm.fk_batch(Q)',
    'jacobian_batch': 'arm.jacobian_batch(Q)',
    'fk_and_jacobian_batch': 'arm.fk_and_jacobian_batch(Q)',
}


def measure(rounds: int, batch: int, min_time_s: float) -> tuple[dict, dict]:
    """Median time per call [us] of each single call and per configuration of each batch form."""
    rng = np.random.default_rng(7)
    arm = FlexibleArm(link_length=0.6, spring_offset=0.03)
    q = rng.uniform(-np.pi, np.pi, arm.n_joints)
    Q = rng.uniform(-np.pi, np.pi, (batch, arm.n_joints))
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
    single = interleaved(SINGLE, rounds, min_time_s=min_time_s, namespace=namespace)
    batched = interleaved(BATCH, max(5, rounds // 3), min_time_s=2.5 * min_time_s,
                          namespace=namespace)
    return ({name: t.median_us for name, t in single.items()},
            {name: t.median_us / batch for name, t in batched.items()})


def rows(single: dict, batch: dict, n: int) -> list[Row]:
    """The headline rows: one call against bare Pinocchio and the numpy chain, the batch forms
    against one call per configuration."""
    ours = single['FlexibleArm.fk_and_jacobian']
    loop = 'one fk_and_jacobian call per configuration'
    return [
        Row('FlexibleArm.fk_and_jacobian, one call', ours, 'us', BARE, single[BARE],
            note='7 DOF, median of round-robin rounds; ' + SINGLE_TARGET_DROPPED),
        Row('FlexibleArm.fk_and_jacobian, one call', ours, 'us',
            'bare J + pose, cached oMf reference',
            single['bare J + pose, cached oMf reference'], note='the same outputs, unvalidated'),
        Row('numpy DH chain (dh_jacobian_reference)',
            single['numpy DH chain (dh_jacobian_reference)'], 'us',
            'FlexibleArm.fk_and_jacobian', ours),
    ] + [Row(f'{name}, per configuration', t, 'us', loop, ours, Target(at_most=TARGET_BATCH_US),
             f'N = {n}') for name, t in batch.items()]


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: 3 rounds, N = 1,000, short batches)."""
    rounds, n, min_time_s = (3, 1000, 0.005) if quick else (31, 10_000, 0.02)
    return rows(*measure(rounds, n, min_time_s), n)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rounds', type=int, default=31, help='round-robin rounds')
    parser.add_argument('--batch', type=int, default=10_000, help='N for the batch forms')
    args = parser.parse_args(argv)

    single, batch = measure(args.rounds, args.batch, 0.02)
    bare = single[BARE]
    print(f'single configuration, FlexibleArm (7 DOF), median of {args.rounds} rounds')
    print(f'{"call":42s} {"us/call":>9s} {"x bare J":>11s}')
    for name, t in single.items():
        print(f'{name:42s} {t:9.3f} {t / bare:11.2f}')
    loop = single['FlexibleArm.fk_and_jacobian']
    print()
    print(f'batch, N = {args.batch}, per configuration')
    print(f'{"call":42s} {"us/config":>9s} {"x loop":>11s}')
    for name, per_config in batch.items():
        print(f'{name:42s} {per_config:9.3f} {per_config / loop:11.2f}')
    print('(x loop: against one fk_and_jacobian call per configuration)')
    print()
    print_rows('kinematics', rows(single, batch, args.batch))
    return 0


if __name__ == '__main__':
    sys.exit(main())
