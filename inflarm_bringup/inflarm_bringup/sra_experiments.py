"""Figs 7-8 of ``001_b59ad71c956a1751`` on the simulated soft arm: PID alone vs PID + ILC.

Section 3.3: the end moves from (0, 0, 604) mm to (100, 110, 670) mm, 30 times. Trial 1 has no
memory (PID alone); every later trial uses the memory learned by the one before. Fig 7 compares
x, y, z against time for trials 1 and 30, Fig 8 the RMSE per trial and axis.

Run ``inflarm-sra-experiments --out DIR`` to write into ``DIR``:

- ``fig7_trajectories.png``: x, y, z [mm] against time [s], trials 1 and 30, target dashed;
- ``fig8_rmse.png``: RMSE [mm] per trial and axis;
- ``trials.csv``: per trial, RMSE [mm] and reach time [s] per axis;
- ``trajectories.csv``: time [s] and x, y, z [mm] of trials 1 and 30;
- ``summary.md``: the set-up and the figures for trials 1, 10 and 30.

Coordinates are in ``sra_mount`` (metres) in the core and converted to millimetres only here,
at the edge, to match the paper's plots. Matplotlib (Agg) is imported only to draw.
"""

import argparse
import csv
from dataclasses import dataclass
from pathlib import Path
import sys

import numpy as np
import numpy.typing as npt

from inflarm_control.pid_ilc import PidIlcController, PidIlcParams, TrialResults, run_trials
from inflarm_hw.sra_plant import SoftArmPlant, SoftArmPlantParams

FIG7_START = (0.0, 0.0, 0.604)
"""Initial point of section 3.3 in ``sra_mount`` [m]."""

FIG7_TARGET = (0.100, 0.110, 0.670)
"""Target point of section 3.3 in ``sra_mount`` [m]."""


@dataclass(frozen=True)
class SraExperiment:
    """Set-up and outcome of the repeated-task experiment.

    Attributes
    ----------
    start, target : ndarray, shape (3,)
        In ``sra_mount`` [m].
    dt : float
        Control period [s].
    noise_std : float
        Vision noise per axis [m].
    results : TrialResults
        Trajectories, RMSE and reach times of every trial (one task).
    """

    start: npt.NDArray[np.float64]
    target: npt.NDArray[np.float64]
    dt: float
    noise_std: float
    results: TrialResults


def run_experiment(
    n_trials: int = 30,
    duration_s: float = 30.0,
    dt: float = 0.2,
    noise_std: float = 0.0,
    seed: int = 7,
    params: PidIlcParams | None = None,
) -> SraExperiment:
    """Repeat the Fig 7 task on the simulated arm, learning between trials.

    Parameters
    ----------
    n_trials : int
        Repetitions (30 in the paper).
    duration_s : float
        Length of each trial [s].
    dt : float
        Control period [s] (5 Hz in the paper).
    noise_std : float
        Vision noise per axis [m]; 0 for a deterministic run.
    seed : int
        Seed of the noise.
    params : PidIlcParams, optional
        Controller parameters; the defaults otherwise.

    Returns
    -------
    SraExperiment
    """
    plant = SoftArmPlant(1, SoftArmPlantParams(noise_std=noise_std),
                         np.random.default_rng(seed))
    controller = PidIlcController(1, params if params is not None else PidIlcParams())
    results = run_trials(plant, controller, FIG7_START, FIG7_TARGET, n_trials, duration_s, dt)
    return SraExperiment(np.array(FIG7_START), np.array(FIG7_TARGET), dt, noise_std, results)


def _trial_rows(experiment: SraExperiment) -> list[list]:
    r = experiment.results
    return [[t + 1, *(f'{v:.4f}' for v in r.rmse[t, 0] * 1e3),
             *(f'{v:.1f}' for v in r.reach_time[t, 0])] for t in range(len(r.rmse))]


def summary_markdown(experiment: SraExperiment) -> str:
    """Markdown summary: set-up, and RMSE / reach time for trials 1, 10 and the last."""
    r = experiment.results
    n_trials = len(r.rmse)
    increases = np.diff(r.rmse[:, 0], axis=0).max(axis=0) if n_trials > 1 else None
    lines = [
        '# Figs 7-8 on the simulated soft arm',
        '',
        f'Task: ({", ".join(f"{v * 1e3:.0f}" for v in experiment.start)}) mm -> '
        f'({", ".join(f"{v * 1e3:.0f}" for v in experiment.target)}) mm, {n_trials} trials of '
        f'{r.times[-1]:.0f} s at {1.0 / experiment.dt:.0f} Hz, vision noise '
        f'{experiment.noise_std * 1e3:.1f} mm. Trial 1 is PID alone; later trials use the '
        'memory of the trial before.',
        '',
        f'Reach time: first time after which the axis stays within {r.tolerance * 1e3:.0f} mm '
        'of the target until the end of the trial.',
        '',
        '| trial | RMSE x [mm] | RMSE y [mm] | RMSE z [mm] '
        '| reach x [s] | reach y [s] | reach z [s] |',
        '|---:|---:|---:|---:|---:|---:|---:|',
    ]
    for t in sorted({0, min(9, n_trials - 1), n_trials - 1}):
        rmse = r.rmse[t, 0] * 1e3
        reach = r.reach_time[t, 0]
        lines.append(f'| {t + 1} | ' + ' | '.join(f'{v:.2f}' for v in rmse) + ' | '
                     + ' | '.join(f'{v:.1f}' for v in reach) + ' |')
    lines += [
        '',
        'Largest RMSE change from one trial to the next (negative: always decreasing) [mm]: '
        + ', '.join(f'{a} {v * 1e3:+.4f}' for a, v in zip('xyz', increases, strict=True))
        if increases is not None else 'Single trial.',
        '',
    ]
    return '\n'.join(lines)


def write_outputs(experiment: SraExperiment, out_dir: str | Path) -> list[Path]:
    """Write the figures, CSV files and summary of an experiment into ``out_dir``.

    Returns
    -------
    paths : list of Path
        The files written.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    r = experiment.results
    last = len(r.rmse) - 1
    target_mm = experiment.target * 1e3
    written = []

    fig, axes = plt.subplots(3, 1, figsize=(6.0, 7.5), sharex=True)
    for axis, ax in enumerate(axes):
        name = 'xyz'[axis]
        ax.plot(r.times, r.trajectories[0, :, 0, axis] * 1e3, label=f'{name}$^{{1}}$ (PID)')
        if last > 0:
            ax.plot(r.times, r.trajectories[last, :, 0, axis] * 1e3,
                    label=f'{name}$^{{{last + 1}}}$ (PID + ILC)')
        ax.axhline(target_mm[axis], color='k', linestyle='--', linewidth=0.8,
                   label=f'{name}$_d$')
        ax.set_ylabel(f'{name} [mm]')
        ax.legend(loc='lower right', fontsize='small')
    axes[-1].set_xlabel('time [s]')
    fig.suptitle(f'Fig 7: end point, trial 1 vs trial {last + 1}')
    fig.tight_layout()
    written.append(out / 'fig7_trajectories.png')
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(3, 1, figsize=(6.0, 7.5), sharex=True)
    trials = np.arange(1, len(r.rmse) + 1)
    for axis, ax in enumerate(axes):
        ax.plot(trials, r.rmse[:, 0, axis] * 1e3, marker='o', markersize=3)
        ax.set_ylabel(f'RMSE {"xyz"[axis]} [mm]')
    axes[-1].set_xlabel('trial')
    fig.suptitle('Fig 8: RMSE tracking error per trial')
    fig.tight_layout()
    written.append(out / 'fig8_rmse.png')
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)

    written.append(out / 'trials.csv')
    with written[-1].open('w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['trial', 'rmse_x_mm', 'rmse_y_mm', 'rmse_z_mm',
                    'reach_x_s', 'reach_y_s', 'reach_z_s'])
        w.writerows(_trial_rows(experiment))

    written.append(out / 'trajectories.csv')
    with written[-1].open('w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['time_s', 'x1_mm', 'y1_mm', 'z1_mm',
                    f'x{last + 1}_mm', f'y{last + 1}_mm', f'z{last + 1}_mm'])
        for k, t in enumerate(r.times):
            w.writerow([f'{t:.2f}', *(f'{v:.3f}' for v in r.trajectories[0, k, 0] * 1e3),
                        *(f'{v:.3f}' for v in r.trajectories[last, k, 0] * 1e3)])

    written.append(out / 'summary.md')
    written[-1].write_text(summary_markdown(experiment))
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--trials', type=int, default=30, help='repetitions (default 30)')
    parser.add_argument('--duration', type=float, default=30.0,
                        help='length of each trial [s] (default 30)')
    parser.add_argument('--noise-std', type=float, default=0.0,
                        help='vision noise per axis [m] (default 0)')
    parser.add_argument('--seed', type=int, default=7, help='noise seed (default 7)')
    args = parser.parse_args(argv)
    try:
        experiment = run_experiment(args.trials, args.duration, noise_std=args.noise_std,
                                    seed=args.seed)
    except ValueError as error:
        parser.error(str(error))
    paths = write_outputs(experiment, args.out)
    sys.stdout.write(summary_markdown(experiment))
    sys.stdout.write('\n'.join(f'wrote {p}' for p in paths) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
