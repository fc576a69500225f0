"""Speed and truthfulness of the elastostatic estimator and IK (000_ce37cf035a0a87c6, 2.3-2.4).

Prints, with baselines measured in the same run:

- ``LoadTracker.update`` warm from the previous sample along smooth motions (median per call
  [us]; target <= 25 us, or at most 0.35x the cold ``estimate_load_and_pose`` measured beside
  it), the cold estimate, and the estimator of ``main`` on the same samples;
- ``estimate_load_and_pose_batch`` (search included: a millisecond or more a sample) and
  ``solve_load_newton`` (the direct solve alone) on 2,000 samples, per sample [us], against
  ``main``'s batch and solve (target for the solve: no slower than main's); without main, the
  batch against the solve alone (the cost of the search for other admissible loads);
- the IK of a 1,000-waypoint straight-line trajectory [ms] against ``main``'s IK;
- with ``--ambiguity``: how often random torques fit several admissible loads, and the recall
  of the estimator's search against a dense one (1,000 random starts per case; ~1 min).

``main`` is the git branch: its ``inflarm_model.elastostatics``, estimator and IK are loaded
from git into this process under other names, so a branch is measured against the code it
would replace. Where main's three files are this tree's, its baselines are skipped (they would
time the same code twice); where they differ, main's kernels compile once (about a minute) into
a cache beside their copies in the temporary directory, and ``--quick`` skips them.

Candidates are timed round-robin (``common.interleaved``): the machine is shared, so compare
the ratios more than the absolute numbers.

Run: ``source scripts/env.sh && python benchmarks/bench_elastostatic.py [--ambiguity]``
"""

import argparse
import hashlib
import importlib
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time
import types

from common import Row, Target, interleaved, print_rows
import numpy as np

from inflarm_control import elastostatic_ik
from inflarm_estimation.elastostatic import (
    DEFAULT_MAX_FORCE,
    LoadTracker,
    estimate_load_and_pose,
    estimate_load_and_pose_batch,
)
from inflarm_model.elastostatics import (
    MOTOR_INDICES,
    SPRING_INDICES,
    motor_torques,
    solve_load_newton,
    spring_deflections,
)
from inflarm_model.kinematics import FlexibleArm

REPO = Path(__file__).resolve().parents[1]
K = 172.71  # k̄ [N·m/rad]
TRACKER_TARGET_US = 25.0
TRACKER_TARGET_RATIO = 0.35
M, S = list(MOTOR_INDICES), list(SPRING_INDICES)
MAIN_SOURCES = {'inflarm_model/inflarm_model/elastostatics.py': 'main_elastostatics',
                'inflarm_estimation/inflarm_estimation/elastostatic.py': 'main_estimator',
                'inflarm_control/inflarm_control/elastostatic_ik.py': 'main_ik'}


def main_modules(quick: bool) -> tuple[dict[str, types.ModuleType] | None, str]:
    """main's elastostatics, estimator and IK (their imports of each other rewritten), or None
    and why not; the modules are files in the temporary directory, so that numba caches them."""
    sources = {}
    for path, name in MAIN_SOURCES.items():
        try:
            sources[name] = subprocess.run(['git', 'show', f'main:{path}'], check=True, cwd=REPO,
                                           capture_output=True, text=True).stdout
        except (OSError, subprocess.CalledProcessError):
            return None, 'no main branch in git'
    if all(sources[name] == (REPO / path).read_text() for path, name in MAIN_SOURCES.items()):
        return None, "main's three files are this tree's"
    if quick:
        return None, "not in --quick: main's kernels would compile (about a minute)"
    digest = hashlib.sha256(''.join(sources.values()).encode()).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / 'inflarm-bench-main' / digest
    folder.mkdir(parents=True, exist_ok=True)
    for name, source in sources.items():
        file = folder / f'{name}.py'
        if not file.exists():  # kept as it is: numba's cache is keyed by the file's stamp
            file.write_text(source.replace('from inflarm_model.elastostatics import',
                                           'from main_elastostatics import'))
    sys.path.insert(0, str(folder))
    try:
        return {name: importlib.import_module(name) for name in sources}, 'main'
    finally:
        sys.path.remove(str(folder))


def cases(arm, n, max_force, rng):
    """Random motor angles and loads with their exact motor torques (forward problem)."""
    Q_m = rng.uniform([-np.pi, -np.pi / 2, -2.6], [np.pi, np.pi / 2, 2.6], (n, 3))
    d = rng.normal(size=(n, 3))
    F = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.0, max_force, (n, 1))
    eq = spring_deflections(arm, Q_m, F, K)
    ok = eq.converged
    Q = np.zeros((ok.sum(), 7))
    Q[:, M], Q[:, S] = Q_m[ok], eq.q_k[ok]
    return Q_m[ok], motor_torques(arm, Q, F[ok]), F[ok]


def motion(arm, rng, samples=400, duration=4.0, max_force=100.0):
    """A smooth motion (as in the tests) with the load ramping to max_force: q_m, tau_m."""
    t = np.linspace(0.0, duration, samples)[:, None]
    q_m = rng.uniform([-2.0, -0.8, 0.6], [2.0, 0.8, 1.8]) + 0.3 * np.sin(
        2 * np.pi * rng.uniform(0.05, 0.3, 3) * t + rng.uniform(0, 6.3, 3))
    direction = rng.normal(size=3)
    forces = direction / np.linalg.norm(direction) * max_force * t / duration
    eq = spring_deflections(arm, q_m, forces, K)
    Q = np.zeros((samples, 7))
    Q[:, M], Q[:, S] = q_m, eq.q_k
    return q_m, motor_torques(arm, Q, forces)


def bench_tracker(arm, old, motions: int, rounds: int) -> dict:
    """Warm updates along smooth motions [us each], and every 20th sample's cold estimate by
    this tree and by main [us, median over ``rounds``]."""
    rng = np.random.default_rng(7)
    warm, cold, before, main_warm = [], [], [], []
    clock = time.perf_counter
    for _ in range(motions):
        q_m, tau = motion(arm, rng)
        tracker = LoadTracker(arm, K)
        main_tracker = old.LoadTracker(arm, K) if old is not None else None
        for i in range(len(q_m)):
            starts = tracker.cold_starts
            t0 = clock()
            tracker.update(q_m[i], tau[i])
            elapsed = (clock() - t0) * 1e6
            if tracker.cold_starts == starts:  # a warm update
                warm.append(elapsed)
            if main_tracker is not None:  # main's tracker on the same sample, right after
                starts = main_tracker.cold_starts
                t0 = clock()
                main_tracker.update(q_m[i], tau[i])
                elapsed = (clock() - t0) * 1e6
                if main_tracker.cold_starts == starts:
                    main_warm.append(elapsed)
            if i % 20 == 10:
                sample = (arm, q_m[i], tau[i], K)
                calls = {'cold': lambda s=sample: estimate_load_and_pose(*s)}
                if old is not None:
                    calls['main'] = lambda s=sample: old.estimate_load_and_pose(*s)
                timing = interleaved(calls, rounds, number=1)
                cold.append(timing['cold'].median_us)
                if old is not None:
                    before.append(timing['main'].median_us)
    return {'warm': warm, 'cold': cold, 'main': before, 'main_warm': main_warm}


def bench_batch(arm, old, n: int, rounds: int) -> dict:
    """Per sample [us]: the batch estimate (search included) and the direct solve alone, here
    and in main, over about ``n`` random samples with loads <= 20 N; convergence, ambiguity."""
    rng = np.random.default_rng(11)
    Q_m, Tau, _ = cases(arm, n, 20.0, rng)
    N = len(Q_m)
    results = {}

    def batch_estimate():  # the slow one (~1 ms a sample): its timed calls give the results
        results['batch'] = estimate_load_and_pose_batch(arm, Q_m, Tau, K)

    direct = solve_load_newton(arm, Q_m, Tau, K)  # the results, and a warm-up of the kernels
    calls = {'batch': batch_estimate, 'solve': lambda: solve_load_newton(arm, Q_m, Tau, K)}
    if old is not None:
        estimator, model = old['main_estimator'], old['main_elastostatics']
        estimator.estimate_load_and_pose_batch(arm, Q_m[:8], Tau[:8], K)  # a warm-up
        model.solve_load_newton(arm, Q_m, Tau, K)
        calls['main batch'] = lambda: estimator.estimate_load_and_pose_batch(arm, Q_m, Tau, K)
        calls['main solve'] = lambda: model.solve_load_newton(arm, Q_m, Tau, K)
    timing = interleaved(calls, rounds, number=1)
    batch = results['batch']
    return {'n': N, **{name: t.median_us / N for name, t in timing.items()},
            'converged': batch.converged.mean(), 'ambiguous': (batch.status == 'ambiguous').mean(),
            'solve_converged': np.mean(direct.converged)}


def bench_ik(arm, old_ik, waypoints: int, rounds: int) -> dict:
    """Wall time [ms] of track_trajectory along a straight line, both methods, here and main."""
    force = np.array([0.0, 10.0, -15.0])
    times, x_d, v_d = elastostatic_ik.straight_line_trajectory((0.6, -0.5, 0.2),
                                                               (0.7, 0.5, 0.6), 10.0, waypoints)
    q0 = elastostatic_ik.solve_ik(arm, x_d[0], force, K, np.array([0.0, 0.6, -1.2]))
    calls = {}
    for label, module in (('', elastostatic_ik), ('main ', old_ik)):
        for method in ('paper', 'effective'):
            if module is not None:
                calls[f'{label}{method}'] = lambda m=module, method=method: m.track_trajectory(
                    arm, times, x_d, v_d, force, K, q0, 50.0, method=method)
    for call in calls.values():
        call()  # warm-up
    return {name: t.median_ms for name, t in interleaved(calls, rounds, number=1).items()}


def bench_ambiguity(arm, n=400, max_force=100.0, dense=1000) -> dict:
    """Fraction of random cases with several admissible loads, and the search's recall."""
    rng = np.random.default_rng(13)
    Q_m, Tau, F = cases(arm, n, max_force, rng)
    estimates = estimate_load_and_pose_batch(arm, Q_m, Tau, K)
    N = len(Q_m)
    starts = rng.uniform(-np.pi / 2, np.pi / 2, (N, dense, 4)) * rng.uniform(0, 1, (N, dense, 1))
    sol = solve_load_newton(arm, np.repeat(Q_m, dense, 0), np.repeat(Tau, dense, 0), K,
                            q_k0=starts.reshape(-1, 4), max_iterations=30)
    ok = (sol.converged & (np.linalg.norm(np.nan_to_num(sol.force, nan=np.inf), axis=-1)
                           <= DEFAULT_MAX_FORCE)).reshape(N, dense)
    q = sol.q_k.reshape(N, dense, 4)
    counts, missed, wrong = [], 0, 0
    for i in range(N):
        roots = []
        for j in np.flatnonzero(ok[i]):
            if all(np.abs(q[i, j] - r).max() > 1e-6 for r in roots):
                roots.append(q[i, j])
        counts.append(len(roots))
        e = estimates[i]
        mine = 1 if e.converged else len(e.alternatives)
        missed += max(0, len(roots) - mine)
        wrong += e.converged and np.abs(e.force - F[i]).max() > 1e-6
    counts = np.array(counts)
    return {'n': N, 'max_force': max_force, 'dense': dense, 'one': np.mean(counts == 1),
            'two': np.mean(counts == 2), 'more': np.mean(counts >= 3),
            'converged': estimates.converged.mean(),
            'ambiguous': np.mean(estimates.status == 'ambiguous'),
            'other': np.mean(~estimates.converged & (estimates.status != 'ambiguous')),
            'missed': int(missed), 'wrong': int(wrong)}


def measure(quick: bool, ambiguity: bool) -> dict:
    """Every figure of the benchmark (--quick: smaller sizes, no main compiled)."""
    arm = FlexibleArm()
    old, why = main_modules(quick)
    sizes = dict(motions=1, cold_rounds=3, n=300, batch_rounds=1, waypoints=200, ik_rounds=1
                 ) if quick else dict(motions=3, cold_rounds=5, n=2000, batch_rounds=2,
                                      waypoints=1000, ik_rounds=3)
    return {
        'main': why, 'sizes': sizes,
        'tracker': bench_tracker(arm, old and old['main_estimator'], sizes['motions'],
                                 sizes['cold_rounds']),
        'batch': bench_batch(arm, old, sizes['n'], sizes['batch_rounds']),
        'ik': bench_ik(arm, old and old['main_ik'], sizes['waypoints'], sizes['ik_rounds']),
        'ambiguity': bench_ambiguity(arm) if ambiguity else None,
    }


def rows(m: dict) -> list[Row]:
    """The summary rows of `measure`'s figures."""
    tracker, batch, ik, why = m['tracker'], m['batch'], m['ik'], m['main']
    have_main = why == 'main'
    no_main = f'no main baseline: {why}'
    warm, cold = statistics.median(tracker['warm']), statistics.median(tracker['cold'])
    out = [
        Row('LoadTracker.update, warm', warm, 'us', 'cold estimate_load_and_pose', cold,
            Target(at_most=TRACKER_TARGET_US, ratio_at_most=TRACKER_TARGET_RATIO),
            f"{len(tracker['warm'])} updates along smooth motions to 100 N, p90 "
            f"{np.percentile(tracker['warm'], 90):.1f} us"),
        Row('LoadTracker.update, warm', warm, 'us', *(
            ("main's LoadTracker.update, warm", statistics.median(tracker['main_warm']))
            if tracker['main_warm'] else ('', None)),
            note='the same samples, timed alternately' if tracker['main_warm'] else no_main),
        Row('estimate_load_and_pose, cold (search included)', cold, 'us',
            *(("main's estimate_load_and_pose", statistics.median(tracker['main']))
              if have_main else ('', None)), note='' if have_main else no_main),
        Row('estimate_load_and_pose_batch, per sample', batch['batch'], 'us',
            *(("main's estimate_load_and_pose_batch", batch['main batch'])
              if have_main else ('solve_load_newton alone', batch['solve'])),
            note=f"{batch['n']} samples, loads <= 20 N, search included; converged "
                 f"{batch['converged']:.1%}, ambiguous {batch['ambiguous']:.1%}"),
        Row('solve_load_newton, per sample', batch['solve'], 'us',
            *(("main's solve_load_newton", batch['main solve'], Target(ratio_at_most=1.0))
              if have_main else ('', None, None)),
            note=(f"converged {batch['solve_converged']:.1%}"
                  + ('; target: no slower than main' if have_main else f'; {no_main}'))),
    ]
    n = m['sizes']['waypoints']
    for method in ('paper', 'effective'):
        if have_main:
            baseline = (f"main's track_trajectory ({method})", ik[f'main {method}'])
        elif method == 'effective':
            baseline = ('track_trajectory (paper)', ik['paper'])
        else:
            baseline = ('', None)
        out.append(Row(f'track_trajectory ({method}), {n} waypoints', ik[method], 'ms',
                       *baseline, note='f_e = (0, 10, -15) N' + ('' if have_main
                                                                  else f'; {no_main}')))
    a = m['ambiguity']
    if a is not None:
        dense = f"dense search, {a['dense']} starts per case"
        context = (f"{a['n']} random cases to {a['max_force']:g} N; several admissible loads in "
                   f"{a['two'] + a['more']:.1%}")
        out += [Row('admissible loads the estimator missed', a['missed'], '', dense,
                    target=Target(at_most=0), note=context),
                Row('converged to a load not the true one', a['wrong'], '', dense,
                    target=Target(at_most=0), note=f"converged {a['converged']:.1%}, ambiguous "
                                                   f"{a['ambiguous']:.1%}")]
    return out


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: one motion, 1,000 samples, 200 waypoints, no
    ambiguity; full: with the ambiguity search, under a minute)."""
    return rows(measure(quick, ambiguity=not quick))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--ambiguity', action='store_true',
                        help='also measure ambiguity and the search recall (about a minute)')
    args = parser.parse_args(argv)
    m = measure(quick=False, ambiguity=args.ambiguity)
    if m['main'] != 'main':
        print(f'baselines of main skipped: {m["main"]}')
    tracker, batch, ik = m['tracker'], m['batch'], m['ik']
    warm, cold = tracker['warm'], statistics.median(tracker['cold'])
    w = statistics.median(warm)
    print(f'LoadTracker.update, warm, smooth motions to 100 N ({len(warm)} samples):')
    print(f'  warm update                 median {w:8.1f} us  p90 {np.percentile(warm, 90):8.1f} '
          f'us  ({w / cold:.3f}x the cold estimate)')
    print(f'  cold estimate (with search) median {cold:8.1f} us')
    if tracker['main_warm']:
        b = statistics.median(tracker['main_warm'])
        print(f"  main's warm update          median {b:8.1f} us  (this one {w / b:.3f}x it)")
    if tracker['main']:
        b = statistics.median(tracker['main'])
        print(f'  main estimate_load_and_pose median {b:8.1f} us  (warm update {w / b:.2f}x it)')
    print(f"batch of {batch['n']} samples (loads <= 20 N):")
    print(f"  estimate_load_and_pose_batch {batch['batch']:8.2f} us per sample (search "
          f"included); converged {batch['converged']:.2%}, ambiguous {batch['ambiguous']:.2%}")
    print(f"  solve_load_newton alone      {batch['solve']:8.2f} us per sample; converged "
          f"{batch['solve_converged']:.2%}")
    if 'main batch' in batch:
        print(f"  main batch                   {batch['main batch']:8.2f} us per sample "
              f"({batch['batch'] / batch['main batch']:.2f}x it), main's solve alone "
              f"{batch['main solve']:.2f} us ({batch['solve'] / batch['main solve']:.2f}x it)")
    print(f"IK of a {m['sizes']['waypoints']}-waypoint trajectory (f_e = (0, 10, -15) N):")
    for method in ('paper', 'effective'):
        versus = (f"  (main {ik[f'main {method}']:6.1f} ms, "
                  f"{ik[method] / ik[f'main {method}']:.2f}x)" if f'main {method}' in ik else '')
        print(f'  track_trajectory ({method:9s}) {ik[method]:6.1f} ms{versus}')
    a = m['ambiguity']
    if a is not None:
        print(f"ambiguity, {a['n']} random cases, loads <= {a['max_force']:g} N, admissible "
              f'|f| <= {DEFAULT_MAX_FORCE:g} N:')
        print(f"  dense search ({a['dense']} starts): one admissible load {a['one']:.1%}, two "
              f"{a['two']:.1%}, three or more {a['more']:.1%}")
        print(f"  estimator: converged {a['converged']:.1%}, ambiguous {a['ambiguous']:.1%}, "
              f"other {a['other']:.1%}; loads the dense search found and the estimator did "
              f"not: {a['missed']}; converged but not the true load: {a['wrong']}")
    print()
    print_rows('elastostatic', rows(m))
    return 0


if __name__ == '__main__':
    sys.exit(main())
