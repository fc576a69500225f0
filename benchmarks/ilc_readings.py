"""Readings of eq. (1) of 001_... compared on the simulated arm: the table of
``inflarm_control/README.md`` ("The ILC term: readings of eq. (1)").

Not a speed benchmark: it backs the README's learning figures. The Fig 7 task, 30 trials of
30 s at 5 Hz, measured exactly, three readings of the ILC term, each with three caps ``P_set``
of eq. (4) (the controller's defaults, and 1.0 and 1.1 x the pressures that hold the Fig 7
target, which the paper's "set according to the experimental results" allows), on the ideal
plant (instantaneous valves) and the default one (valves 0.1 s behind their commands):

- A, literal: the increment of every step adds ``min(P^{t-1}_{out,k}, P_set)`` (eq. 1) and
  eq. (3) accumulates it; the memory is the recorded output;
- B, memory of the output: feedforward ``min(P^{t-1}_{out,k}, P_set)``, the PID accumulated on
  top (eq. 3), the memory is the recorded output of this trial;
- C, implemented: `PidIlcController.finish_trial`'s phase-lead update.

Only public API: B and C run `PidIlcController` (B keeps its commands as the next memory), A
is the literal update written out below. ``python benchmarks/ilc_readings.py`` (about 15 s).
"""

import numpy as np

from inflarm_control.pid_ilc import PidIlcController, PidIlcParams, run_trials
from inflarm_control.trial_metrics import TrialMetrics
from inflarm_hw.sra_plant import IDEAL, NOISE_FREE, SoftArmPlant
from inflarm_model.soft_arm import BELLOWS_PUSH, CHAMBERS

START = np.array([0.0, 0.0, 0.604])
TARGET = np.array([0.100, 0.110, 0.670])
TRIALS, DURATION_S, DT = 30, 30.0, 0.2
STEPS = int(round(DURATION_S / DT))


Figures = tuple[np.ndarray, np.ndarray]  # RMSE [m], reach time [s], each (trials, 3)


def reading_a(plant: SoftArmPlant, params: PidIlcParams) -> Figures:
    """Eq. (1) + (3) read literally (K_I = K_D = 0, as the defaults): per step
    ``P_k = clip(P_{k-1} + K_P e_k + min(P^{t-1}_k, P_set), 0, P_max)``."""
    probe = PidIlcController(1, params)
    probe.start_trial(START, TARGET)
    chamber = probe.chamber_of_axis[0]
    sign = np.array([BELLOWS_PUSH[CHAMBERS[chamber[0]]][0],
                     BELLOWS_PUSH[CHAMBERS[chamber[1]]][1], 1.0])
    kp, p_set = np.asarray(params.kp), np.asarray(params.p_set)
    p_max = np.asarray(params.p_max)[chamber]
    previous, rmse, reach = None, [], []
    for _ in range(TRIALS):
        plant.reset(end_point=START)
        output = plant.chamber_pressures[0, chamber]
        recorded, metrics = [], TrialMetrics(TARGET, 0.005)
        for k in range(STEPS + 1):
            y = plant.measure()[0]
            metrics.add(y, k * DT)
            if k == STEPS:
                break
            ilc = 0.0 if previous is None else np.minimum(
                previous[min(k, params.memory_steps - 1)], p_set)
            output = np.clip(output + kp * sign * (TARGET - y) + ilc, 0.0, p_max)
            if k < params.memory_steps:
                recorded.append(output)
            command = np.zeros(len(CHAMBERS))
            command[chamber] = output
            plant.step(command, DT)
        previous = np.array(recorded)
        rmse.append(metrics.rmse[0])
        reach.append(metrics.reach_time[0])
    return np.array(rmse), np.array(reach)


def reading_b(plant: SoftArmPlant, params: PidIlcParams) -> Figures:
    """The controller's feedforward and eq. (3), the recorded outputs as the next memory."""
    controller = PidIlcController(1, params)
    memory, rmse, reach = None, [], []
    for _ in range(TRIALS):
        plant.reset(end_point=START)
        controller.start_trial(START, TARGET, memory, initial_output=plant.chamber_pressures)
        recorded, metrics = [], TrialMetrics(TARGET, 0.005)
        for k in range(STEPS + 1):
            y = plant.measure()
            metrics.add(y, k * DT)
            if k < STEPS:
                command = controller.step(y, DT)
                recorded.append(command[0])
                plant.step(command, DT)
        controller.finish_trial()  # reading C's memory, discarded
        memory = np.array(recorded[:params.memory_steps])
        rmse.append(metrics.rmse[0])
        reach.append(metrics.reach_time[0])
    return np.array(rmse), np.array(reach)


def reading_c(plant: SoftArmPlant, params: PidIlcParams) -> Figures:
    r = run_trials(plant, PidIlcController(1, params), START, TARGET, TRIALS, DURATION_S, DT,
                   keep_trajectories=False)
    return r.rmse[:, 0], r.reach_time[:, 0]


def main() -> None:
    readings = {'A literal': reading_a, 'B output memory': reading_b, 'C implemented': reading_c}
    plants = {'ideal plant': IDEAL, 'default plant (valve delay 0.1 s), exact measurement':
              NOISE_FREE}
    for plant_name, plant_params in plants.items():
        hold = SoftArmPlant(1, plant_params).holding_pressures(TARGET)[0]
        hold_axes = np.array([hold[CHAMBERS.index('B4')], hold[CHAMBERS.index('B3')],
                              hold[CHAMBERS.index('PEA')]])
        caps = {'default': PidIlcParams().p_set, '1.0 x hold': tuple(hold_axes),
                '1.1 x hold': tuple(1.1 * hold_axes)}
        print(f'\n{plant_name}; holding pressures of the target B4, B3, PEA: '
              f'{", ".join(f"{p / 1e3:.1f}" for p in hold_axes)} kPa')
        print('| reading | P_set x, y, z [kPa] | RMSE x, y, z at trial 1 [mm] | at 10 | at 30 '
              '| RMSE rises (x, y, z), largest [mm] | reach x, y, z at 30 [s] |')
        print('|---|---|---|---|---|---|---|')
        for cap_name, cap in caps.items():
            params = PidIlcParams(p_set=cap)
            for name, run in readings.items():
                rmse, reach = run(SoftArmPlant(1, plant_params), params)
                mm = rmse * 1e3
                rises = np.diff(mm, axis=0)
                cells = [', '.join(f'{v:.1f}' for v in mm[t]) for t in (0, 9, 29)]
                print(f'| {name} | {cap_name}: {", ".join(f"{p / 1e3:.1f}" for p in cap)} | '
                      + ' | '.join(cells)
                      + f' | {", ".join(str(int(n)) for n in (rises > 0).sum(axis=0))}; '
                      f'{rises.max():+.2f} | {", ".join(f"{v:.1f}" for v in reach[29])} |',
                      flush=True)


if __name__ == '__main__':
    main()
