"""Speed of the elastostatic estimator and IK (sections 2.3-2.4 of 000_ce37cf035a0a87c6).

Prints, with baselines measured in the same run:

- a converged ``estimate_load_and_pose`` per call [us], median over random configurations
  and loads (target <= 25 us), against the plain fixed point of Fig. 5 iterated to the same
  residual (1e-10 N·m) with (a) Pinocchio's Jacobian (``arm.jacobian``) and
  ``np.linalg.solve`` and (b) the textbook DH Jacobian (``dh_jacobian_reference``);
- ``estimate_load_and_pose_batch`` on 10,000 samples, per sample [us] (target <= 5 us);
- the IK of a 1,000-waypoint straight-line trajectory [ms] (target <= 100 ms):
  ``track_trajectory`` (eq. 9, both velocity maps) and ``solve_ik`` at every waypoint,
  warm-started from the previous one.

Per-call figures are the best of 5 repeats of each case, so other load on the machine inflates
them less; the machine is shared, so compare the ratios more than the absolute numbers.

Run: ``PYTHONPATH=inflarm_model:inflarm_estimation:inflarm_control .venv/bin/python
benchmarks/bench_elastostatic.py [--cases 200] [--max-force 20]``
"""

import argparse
import statistics
import time
import timeit

import numpy as np

from inflarm_control.elastostatic_ik import solve_ik, straight_line_trajectory, track_trajectory
from inflarm_estimation.elastostatic import estimate_load_and_pose, estimate_load_and_pose_batch
from inflarm_model.elastostatics import (
    MOTOR_INDICES,
    SPRING_INDICES,
    motor_torques_batch,
    spring_deflections_batch,
)
from inflarm_model.kinematics import FlexibleArm, dh_jacobian_reference

K = 172.71  # k̄ [N·m/rad]
TOL = 1e-10  # residual tolerance [N·m], the estimator's default
SINGLE_TARGET_US = 25.0
BATCH_TARGET_US = 5.0
IK_TARGET_MS = 100.0
M, S = list(MOTOR_INDICES), list(SPRING_INDICES)


def cases(arm, n, max_force, rng):
    """Random motor angles and loads with their exact motor torques (forward problem)."""
    Q_m = rng.uniform([-np.pi, -np.pi / 2, -2.6], [np.pi, np.pi / 2, 2.6], (n, 3))
    d = rng.normal(size=(n, 3))
    F = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.0, max_force, (n, 1))
    eq = spring_deflections_batch(arm, Q_m, F, K)
    Q = np.zeros((n, 7))
    Q[:, M], Q[:, S] = Q_m, eq.q_k
    ok = eq.converged
    return Q_m[ok], motor_torques_batch(arm, Q[ok], F[ok]), F[ok]


def fixed_point(jacobian, q_m, tau_m, max_iterations=200):
    """Fig. 5 in plain numpy: f = U_m^-T tau_m, q_k = U_k^T f / k, to the residual TOL."""
    q = np.zeros(7)
    q[M] = q_m
    for _ in range(max_iterations):
        U = jacobian(q)[:3]
        f = np.linalg.solve(U[:, M].T, tau_m)
        g = K * q[S] - U[:, S].T @ f
        if np.abs(g).max() <= TOL:
            return f
        q[S] = U[:, S].T @ f / K
    return None


def per_call_us(fn, repeat=5, number=3):
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def bench_single(arm, n, max_force):
    rng = np.random.default_rng(7)
    Q_m, Tau, F = cases(arm, n, max_force, rng)
    ours, pin_fp, ref_fp = [], [], []
    for q_m, tau, f in zip(Q_m, Tau, F, strict=True):
        est = estimate_load_and_pose(arm, q_m, tau, K)
        if not est.converged or np.abs(est.force - f).max() > 1e-6:
            continue
        ours.append(per_call_us(lambda q_m=q_m, tau=tau: estimate_load_and_pose(arm, q_m, tau,
                                                                                K)))
        if fixed_point(arm.jacobian, q_m, tau) is not None:
            pin_fp.append(per_call_us(lambda q_m=q_m, tau=tau: fixed_point(arm.jacobian, q_m,
                                                                           tau)))
            if len(ref_fp) < 40:  # the textbook chain is slow: a sample is enough

                def ref(q_m=q_m, tau=tau):
                    return fixed_point(lambda q: dh_jacobian_reference(arm.dh_table, q), q_m,
                                       tau)

                ref_fp.append(per_call_us(ref, repeat=2, number=1))
    med = statistics.median(ours)
    print(f'single estimate, loads <= {max_force:g} N, {len(ours)} converged cases:')
    print(f'  estimate_load_and_pose          median {med:7.1f} us  p90 '
          f'{np.percentile(ours, 90):7.1f} us  (target <= {SINGLE_TARGET_US:g} us: '
          f'{"met" if med <= SINGLE_TARGET_US else "NOT met"})')
    for name, times in (('fixed point, Pinocchio J', pin_fp),
                        ('fixed point, textbook DH J', ref_fp)):
        m = statistics.median(times)
        print(f'  {name:30s}  median {m:7.1f} us  ({m / med:5.1f}x slower; converged in '
              f'{len(times)} timed cases)')
    return Q_m, Tau


def bench_batch(arm, n=10_000):
    rng = np.random.default_rng(11)
    Q_m, Tau, _ = cases(arm, n, 20.0, rng)
    t0 = time.perf_counter()
    batch = estimate_load_and_pose_batch(arm, Q_m, Tau, K)
    elapsed = time.perf_counter() - t0
    per = elapsed / len(Q_m) * 1e6
    t0 = time.perf_counter()
    for i in range(500):
        estimate_load_and_pose(arm, Q_m[i], Tau[i], K)
    loop = (time.perf_counter() - t0) / 500 * 1e6
    print(f'batch estimate, {len(Q_m)} samples (loads <= 20 N): {elapsed * 1e3:.1f} ms, '
          f'{per:.2f} us per sample (target <= {BATCH_TARGET_US:g} us: '
          f'{"met" if per <= BATCH_TARGET_US else "NOT met"}); single calls in a loop '
          f'{loop:.1f} us each ({loop / per:.1f}x); converged {batch.converged.mean():.2%}')


def bench_ik(arm):
    force = np.array([0.0, 10.0, -15.0])
    times, x_d, v_d = straight_line_trajectory((0.6, -0.5, 0.2), (0.7, 0.5, 0.6), 10.0, 1000)
    q0 = solve_ik(arm, x_d[0], force, K, np.array([0.0, 0.6, -1.2]))
    print('IK of a 1,000-waypoint trajectory (f_e = (0, 10, -15) N):')
    for method in ('paper', 'effective'):
        best = min(timeit.repeat(
            lambda method=method: track_trajectory(arm, times, x_d, v_d, force, K, q0, 50.0,
                                                   method=method), number=1, repeat=3))
        result = track_trajectory(arm, times, x_d, v_d, force, K, q0, 50.0, method=method)
        print(f'  track_trajectory ({method:9s}) {best * 1e3:6.1f} ms  (target <= '
              f'{IK_TARGET_MS:g} ms: {"met" if best * 1e3 <= IK_TARGET_MS else "NOT met"}); '
              f'tip error max {result.tip_error.max() * 1e3:.3f} mm')

    def point_ik():
        q = q0
        for x in x_d:
            q = solve_ik(arm, x, force, K, q)

    best = min(timeit.repeat(point_ik, number=1, repeat=3))
    print(f'  solve_ik at every waypoint     {best * 1e3:6.1f} ms  (each to 1e-10 m)')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--cases', type=int, default=200, help='random cases per load range')
    parser.add_argument('--max-force', type=float, default=20.0,
                        help='largest load of the single-call cases [N] (default 20)')
    args = parser.parse_args()
    arm = FlexibleArm()
    bench_single(arm, args.cases, args.max_force)
    bench_single(arm, args.cases // 2, 100.0)
    bench_batch(arm)
    bench_ik(arm)


if __name__ == '__main__':
    main()
