"""Speed of the PID + ILC controller core against a bare numpy PID update, measured in one run.

Target (issue 5): a controller step costs <= 5 us per axis, ILC included. Measured:

- ``PidIlcController.step`` for n = 1 (the ROS node) and n = 10,000 tasks (building the
  experiential knowledge database), per step and per axis (step time / (3 n));
- the ILC learning of ``finish_trial`` amortized over the ``memory_steps`` steps it covers;
- a baseline: the bare numpy velocity-form PID update of eqs. (1) and (3) on the same arrays
  (no validation, quadrant mapping, feedforward or recording), and the simulated plant's step.

Usage: ``PYTHONPATH=inflarm_model:inflarm_control:inflarm_hw python benchmarks/bench_pid_ilc.py``
"""

import time

import numpy as np

from inflarm_control.pid_ilc import PidIlcController
from inflarm_hw.sra_plant import SoftArmPlant

START = (0.0, 0.0, 0.604)
TARGET = (0.100, 0.110, 0.670)
TARGET_US_PER_AXIS = 5.0


def _best_of(fn, repeats: int, number: int) -> float:
    """Smallest mean time of one call [s] over ``repeats`` batches of ``number`` calls."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def _baseline_pid(n: int):
    kp, ki, kd = np.array([1e4, 1e4, 3e3]), np.zeros(3), np.zeros(3)
    target = np.tile(TARGET, (n, 1))
    y = np.tile(START, (n, 1))
    state = {'out': np.zeros((n, 3)), 'integral': np.zeros((n, 3)), 'prev': np.zeros((n, 3))}

    def step():
        e = target - y
        state['integral'] += e * 0.2
        state['out'] = np.clip(state['out'] + kp * e + ki * state['integral']
                               + kd * (e - state['prev']) / 0.2, 0.0, 100e3)
        state['prev'] = e
        return state['out']

    return step


def _controller_step(n: int):
    controller = PidIlcController(n)
    memory = np.full((n, controller.params.memory_steps, 5), 10e3)
    controller.start_trial(START, TARGET, memory=memory)
    y = np.tile(START, (n, 1))
    calls = [0]

    def step():
        if calls[0] == 150:  # a 30 s trial; restart so the memory is in use throughout
            controller.finish_trial()
            controller.start_trial(START, TARGET, memory=memory)
            calls[0] = 0
        calls[0] += 1
        return controller.step(y, 0.2)

    return step, controller, memory


def _finish_trial(n: int) -> float:
    controller = PidIlcController(n)
    memory = np.full((n, controller.params.memory_steps, 5), 10e3)
    y = np.tile(START, (n, 1))
    best = np.inf
    for _ in range(3 if n > 1 else 30):
        controller.start_trial(START, TARGET, memory=memory)
        for _ in range(150):
            controller.step(y, 0.2)
        t0 = time.perf_counter()
        controller.finish_trial()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    rows = []
    for n, repeats, number in ((1, 7, 3000), (10_000, 5, 20)):
        baseline = _best_of(_baseline_pid(n), repeats, number)
        step, controller, _ = _controller_step(n)
        core = _best_of(step, repeats, number)
        learn = _finish_trial(n) / controller.params.memory_steps
        plant = SoftArmPlant(n)
        command = np.zeros((n, 5))
        plant_step = _best_of(lambda p=plant, c=command: p.step(c, 0.2), repeats,
                              max(1, number // 4))
        rows.append((n, baseline, core, learn, plant_step))

    print('PID + ILC controller core (inflarm_control.pid_ilc), best-of timings')
    print(f'{"n":>7} {"baseline PID":>14} {"step":>12} {"step+ILC":>12} '
          f'{"per axis":>10} {"vs baseline":>12} {"plant step":>12}')
    for n, baseline, core, learn, plant_step in rows:
        total = core + learn
        per_axis = total / (3 * n)
        print(f'{n:>7} {baseline * 1e6:>11.2f} us {core * 1e6:>9.2f} us {total * 1e6:>9.2f} us '
              f'{per_axis * 1e6:>7.3f} us {total / baseline:>11.2f}x {plant_step * 1e6:>9.1f} us')
    print()
    print('step: PidIlcController.step (validation, quadrant mapping, feedforward, PID, '
          'anti-windup, recording)')
    print('step+ILC: plus finish_trial (the learning update) amortized over memory_steps')
    for n, _, core, learn, _ in rows:
        per_axis = (core + learn) / (3 * n) * 1e6
        verdict = 'meets' if per_axis <= TARGET_US_PER_AXIS else 'misses'
        print(f'n = {n}: {per_axis:.3f} us per axis {verdict} the {TARGET_US_PER_AXIS:.0f} us '
              f'target ({per_axis / TARGET_US_PER_AXIS:.2f} of it)')


if __name__ == '__main__':
    main()
