"""Figs 7-8 of ``001_b59ad71c956a1751`` on the simulated soft arm: PID alone vs PID + ILC.

Section 3.3: the end moves from (0, 0, 604) mm to (100, 110, 670) mm, 30 times. Trial 1 has no
memory (PID alone); every later trial uses the memory learned by the one before. Fig 7 compares
x, y, z against time for trials 1 and 30, Fig 8 the RMSE per trial and axis.

By default the loop is closed through the camera, as on the prototype: the plant is the default
`inflarm_hw.sra_plant.SoftArmPlant` (valves 0.1 s behind their commands), and at every control
step its true end point is rendered by the soft arm's simulated camera
(`inflarm_hw.synthetic_camera.SraCamera`, the one ``sra_sim`` publishes) and measured by the
vision pipeline ``ball_tracker`` runs (`inflarm_vision.pipeline.BallPipeline`, its default
settings). ``--no-camera`` measures with the plant's stand-in instead (the true end point plus
0.5 mm of noise per axis). Every run also repeats the experiment on the ideal plant
(`inflarm_hw.sra_plant.IDEAL`: instantaneous valves, exact measurements), the noise-free
reference, and reports both side by side.

Run ``inflarm-sra-experiments --out DIR`` to write into ``DIR``:

- ``fig7_trajectories.png``: x, y, z [mm] against time [s], trials 1 and 30, target dashed;
- ``fig8_rmse.png``: RMSE [mm] per trial and axis, with the noise-free reference;
- ``trials.csv``: per trial, RMSE [mm] and reach time [s] per axis, measured and true, and
  those of the noise-free reference;
- ``trajectories.csv``: time [s] and measured x, y, z [mm] of trials 1 and 30;
- ``summary.md``: the set-up and the figures for trials 1, 10 and 30.

The camera renders and measures one frame per control step, so the default 30 trials of 30 s
(4,530 frames) are the long run (``inflarm_control/README.md`` has its time) and
``--trials 3 --duration 6`` a short one.
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
from inflarm_control.trial_metrics import TrialMetrics
from inflarm_hw.sra_plant import IDEAL, SoftArmPlant, SoftArmPlantParams
from inflarm_hw.synthetic_camera import SraCamera
from inflarm_vision.pipeline import BallPipeline, TrackerSettings
from inflarm_vision.tracker import DetectorParams

FIG7_START = (0.0, 0.0, 0.604)
"""Initial point of section 3.3 in ``sra_mount`` [m]."""

FIG7_TARGET = (0.100, 0.110, 0.670)
"""Target point of section 3.3 in ``sra_mount`` [m]."""

MEASUREMENTS = ('camera', 'plant')
"""How the end point is measured: rendered and tracked (``'camera'``), or the plant's
`SoftArmPlant.measure` (the true end point plus the camera's error model)."""


class MeasuredPlant:
    """A one-arm plant for `inflarm_control.pid_ilc.run_trials` that keeps the true end point of
    every measurement, and optionally measures through the simulated camera.

    Parameters
    ----------
    plant : SoftArmPlant
        The simulated arm, ``n = 1``.
    camera : SraCamera, optional
        Render the true end point through this camera at every `measure` and locate the ball
        with `BallPipeline` (default detector, the camera's pose and ball: what ``ball_tracker``
        is configured with for ``sra_sim``). None: ``plant.measure()``.
    seed : int
        Seed of the camera's background and sensor noise.

    Attributes
    ----------
    truth : list of ndarray, shape (3,)
        True end point at every `measure` [m].
    frames, dropouts : int
        Camera frames rendered, and those in which the ball was not found (measured as NaN:
        the controller holds and learns nothing from that step).
    """

    def __init__(self, plant: SoftArmPlant, camera: SraCamera | None = None,
                 seed: int = 7) -> None:
        if plant.n != 1:
            raise ValueError(f'expected a plant of one arm, got n = {plant.n}')
        self.plant = plant
        self.n = 1
        self.renderer = None if camera is None else camera.renderer(seed)
        self.pipeline = None if camera is None else BallPipeline(TrackerSettings(
            DetectorParams(), 0.5 * camera.ball_diameter_m, camera.camera2mount()))
        self.truth: list[npt.NDArray[np.float64]] = []
        self.frames = 0
        self.dropouts = 0

    @property
    def chamber_pressures(self) -> npt.NDArray[np.float64]:
        return self.plant.chamber_pressures

    def reset(self, end_point: npt.ArrayLike | None = None) -> None:
        self.plant.reset(end_point=end_point)

    def step(self, pressure_command: npt.ArrayLike, dt: float) -> None:
        self.plant.step(pressure_command, dt)

    def measure(self) -> npt.NDArray[np.float64]:
        """Measured end point, shape (1, 3) [m]; NaN if the camera did not find the ball."""
        truth = self.plant.end_point
        self.truth.append(truth[0])
        if self.renderer is None:
            return self.plant.measure()
        frame = self.renderer.render(truth[0])
        measurement = self.pipeline.process(frame.image, self.renderer.camera)
        self.frames += 1
        if measurement is None:
            self.dropouts += 1
            return np.full((1, 3), np.nan)
        return measurement.position[None, :]


@dataclass(frozen=True)
class SraExperiment:
    """Set-up and outcome of the repeated-task experiment.

    Attributes
    ----------
    start, target : ndarray, shape (3,)
        In ``sra_mount`` [m].
    dt : float
        Control period [s].
    measurement : str
        One of `MEASUREMENTS`, or ``'exact'`` (``plant.measure()`` without noise).
    plant : SoftArmPlantParams
        The simulated arm (valve delay, stand-in noise).
    results : TrialResults
        Measured trajectories, RMSE and reach times of every trial (one task).
    true_rmse, true_reach_time : ndarray, shape (n_trials, 3)
        The same figures for the true end point [m], [s].
    frames, dropouts : int
        Camera frames, and frames without the ball (0 without the camera).
    """

    start: npt.NDArray[np.float64]
    target: npt.NDArray[np.float64]
    dt: float
    measurement: str
    plant: SoftArmPlantParams
    results: TrialResults
    true_rmse: npt.NDArray[np.float64]
    true_reach_time: npt.NDArray[np.float64]
    frames: int
    dropouts: int

    @property
    def label(self) -> str:
        """One line: how the loop was closed and on which plant."""
        how = {'camera': 'camera + ball tracker',
               'plant': (f'stand-in measurement (camera error model, '
                         f'{self.plant.noise_center_px:.3g} / {self.plant.noise_radius_px:.3g} '
                         f'px centre / radius)'),
               }.get(self.measurement, 'exact measurement')
        return f'{how}, valve delay {self.plant.valve_delay:.2f} s'


def run_experiment(
    n_trials: int = 30,
    duration_s: float = 30.0,
    dt: float = 0.2,
    measurement: str = 'camera',
    plant_params: SoftArmPlantParams | None = None,
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
        Control period [s] (5 Hz in the paper; also the camera's rate).
    measurement : str
        ``'camera'`` (rendered and tracked), ``'plant'`` (``plant.measure()``).
    plant_params : SoftArmPlantParams, optional
        The simulated arm; `SoftArmPlantParams` defaults (0.1 s valve delay, the camera's error
        model on the stand-in measurement) otherwise. ``IDEAL`` with ``'plant'`` is the
        noise-free reference.
    seed : int
        Seed of the noise (camera images or stand-in).
    params : PidIlcParams, optional
        Controller parameters; the defaults otherwise.

    Returns
    -------
    SraExperiment
    """
    if measurement not in MEASUREMENTS:
        raise ValueError(f'expected measurement in {list(MEASUREMENTS)}, got {measurement!r}')
    plant_params = SoftArmPlantParams() if plant_params is None else plant_params
    rng = np.random.default_rng(seed)
    plant = MeasuredPlant(SoftArmPlant(1, plant_params, rng),
                          SraCamera() if measurement == 'camera' else None, seed)
    controller = PidIlcController(1, params if params is not None else PidIlcParams())
    results = run_trials(plant, controller, FIG7_START, FIG7_TARGET, n_trials, duration_s, dt)
    truth = np.array(plant.truth).reshape(n_trials, len(results.times), 3)
    true_rmse = np.empty((n_trials, 3))
    true_reach = np.empty((n_trials, 3))
    for t in range(n_trials):
        metrics = TrialMetrics(FIG7_TARGET, results.tolerance)
        for k, time in enumerate(results.times):
            metrics.add(truth[t, k], time)
        true_rmse[t], true_reach[t] = metrics.rmse[0], metrics.reach_time[0]
    if measurement == 'plant' and plant_params.noise_center_px == 0.0 \
            and plant_params.noise_radius_px == 0.0:
        measurement = 'exact'
    return SraExperiment(np.array(FIG7_START), np.array(FIG7_TARGET), dt, measurement,
                         plant_params, results, true_rmse, true_reach, plant.frames,
                         plant.dropouts)


def reference_experiment(n_trials: int = 30, duration_s: float = 30.0,
                         dt: float = 0.2) -> SraExperiment:
    """The noise-free reference: the ideal plant (`IDEAL`), measured exactly."""
    return run_experiment(n_trials, duration_s, dt, 'plant', IDEAL)


def _fmt(values: npt.ArrayLike, scale: float, digits: int) -> list[str]:
    return [f'{v * scale:.{digits}f}' for v in np.asarray(values)]


def _table(experiment: SraExperiment, rows: list[int], true: bool) -> list[str]:
    r = experiment.results
    header = '| trial | RMSE x, y, z [mm] | reach x, y, z [s] |'
    rule = '|---:|---|---|'
    if true:
        header += ' true RMSE x, y, z [mm] | true reach x, y, z [s] |'
        rule += '---|---|'
    lines = [header, rule]
    for t in rows:
        line = (f'| {t + 1} | {", ".join(_fmt(r.rmse[t, 0], 1e3, 2))} | '
                f'{", ".join(_fmt(r.reach_time[t, 0], 1.0, 1))} |')
        if true:
            line += (f' {", ".join(_fmt(experiment.true_rmse[t], 1e3, 2))} | '
                     f'{", ".join(_fmt(experiment.true_reach_time[t], 1.0, 1))} |')
        lines.append(line)
    return lines


def _largest_rise(rmse: npt.NDArray[np.float64]) -> str:
    if len(rmse) < 2:
        return 'single trial'
    rise = np.diff(rmse, axis=0)
    return ', '.join(f'{a} {v * 1e3:+.3f} mm ({n} rises)' for a, v, n in
                     zip('xyz', rise.max(axis=0), (rise > 0.0).sum(axis=0), strict=True))


def summary_markdown(experiment: SraExperiment, reference: SraExperiment | None = None) -> str:
    """Markdown summary: set-up, and RMSE / reach time for trials 1, 10 and the last, of the
    experiment and (if given) of the noise-free reference."""
    r = experiment.results
    n_trials = len(r.rmse)
    rows = sorted({0, min(9, n_trials - 1), n_trials - 1})
    lines = [
        '# Figs 7-8 on the simulated soft arm',
        '',
        f'Task: ({", ".join(f"{v * 1e3:.0f}" for v in experiment.start)}) mm -> '
        f'({", ".join(f"{v * 1e3:.0f}" for v in experiment.target)}) mm, {n_trials} trials of '
        f'{r.times[-1]:.0f} s at {1.0 / experiment.dt:.0f} Hz. Trial 1 is PID alone; later '
        'trials use the memory of the trial before.',
        '',
        f'Reach time: first time after which the axis stays within {r.tolerance * 1e3:.0f} mm '
        'of the target until the end of the trial (inf: outside at the end). RMSE and reach '
        "time are those of the measured end point (as the paper's camera records it); "
        '"true" ones are of the simulated arm\'s true end point.',
        '',
        f'## {experiment.label}',
        '',
    ]
    if experiment.frames:
        lines += [f'Camera frames: {experiment.frames}, ball not found in '
                  f'{experiment.dropouts}.', '']
    lines += _table(experiment, rows, true=experiment.measurement != 'exact')
    lines += ['', f'Largest RMSE rise from one trial to the next: {_largest_rise(r.rmse[:, 0])}.',
              '']
    if reference is not None:
        lines += [f'## Noise-free reference: {reference.label}', '']
        lines += _table(reference, rows, true=False)
        lines += ['', 'Largest RMSE rise from one trial to the next: '
                  f'{_largest_rise(reference.results.rmse[:, 0])}.', '']
    return '\n'.join(lines)


def write_outputs(experiment: SraExperiment, out_dir: str | Path,
                  reference: SraExperiment | None = None) -> list[Path]:
    """Write the figures, CSV files and summary of an experiment (and its noise-free
    reference, if given) into ``out_dir``.

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
    fig.suptitle(f'Fig 7: end point, trial 1 vs trial {last + 1}\n{experiment.label}',
                 fontsize='medium')
    fig.tight_layout()
    written.append(out / 'fig7_trajectories.png')
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(3, 1, figsize=(6.0, 7.5), sharex=True)
    trials = np.arange(1, len(r.rmse) + 1)
    for axis, ax in enumerate(axes):
        ax.plot(trials, r.rmse[:, 0, axis] * 1e3, marker='o', markersize=3,
                label=experiment.label)
        if reference is not None:
            ax.plot(trials, reference.results.rmse[:, 0, axis] * 1e3, marker='.',
                    markersize=3, linestyle=':', label='noise-free reference')
        ax.set_ylabel(f'RMSE {"xyz"[axis]} [mm]')
    axes[0].legend(loc='upper right', fontsize='small')
    axes[-1].set_xlabel('trial')
    fig.suptitle('Fig 8: RMSE tracking error per trial')
    fig.tight_layout()
    written.append(out / 'fig8_rmse.png')
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)

    written.append(out / 'trials.csv')
    with written[-1].open('w', newline='') as f:
        w = csv.writer(f)
        columns = [f'{what}_{a}_{unit}' for what, unit in (('rmse', 'mm'), ('reach', 's'))
                   for a in 'xyz']
        header = ['trial', *columns, *(f'true_{c}' for c in columns)]
        if reference is not None:
            header += [f'reference_{c}' for c in columns]
        w.writerow(header)
        for t in range(len(r.rmse)):
            row = [t + 1, *_fmt(r.rmse[t, 0], 1e3, 4), *_fmt(r.reach_time[t, 0], 1.0, 1),
                   *_fmt(experiment.true_rmse[t], 1e3, 4),
                   *_fmt(experiment.true_reach_time[t], 1.0, 1)]
            if reference is not None:
                row += [*_fmt(reference.results.rmse[t, 0], 1e3, 4),
                        *_fmt(reference.results.reach_time[t, 0], 1.0, 1)]
            w.writerow(row)

    written.append(out / 'trajectories.csv')
    with written[-1].open('w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['time_s', 'x1_mm', 'y1_mm', 'z1_mm',
                    f'x{last + 1}_mm', f'y{last + 1}_mm', f'z{last + 1}_mm'])
        for k, t in enumerate(r.times):
            w.writerow([f'{t:.2f}', *(f'{v:.3f}' for v in r.trajectories[0, k, 0] * 1e3),
                        *(f'{v:.3f}' for v in r.trajectories[last, k, 0] * 1e3)])

    written.append(out / 'summary.md')
    written[-1].write_text(summary_markdown(experiment, reference))
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--trials', type=int, default=30, help='repetitions (default 30)')
    parser.add_argument('--duration', type=float, default=30.0,
                        help='length of each trial [s] (default 30)')
    parser.add_argument('--camera', action=argparse.BooleanOptionalAction, default=True,
                        help='close the loop through the simulated camera and the ball tracker '
                             "(default); --no-camera: the plant's stand-in measurement")
    parser.add_argument('--noise-px', type=float, nargs=2, default=None,
                        metavar=('CENTER', 'RADIUS'),
                        help="image errors behind the stand-in measurement [px] (--no-camera; "
                             "default the plant's 0.12 0.013)")
    parser.add_argument('--valve-delay', type=float, default=None,
                        help="valve transport delay [s] (default the plant's 0.1)")
    parser.add_argument('--seed', type=int, default=7, help='noise seed (default 7)')
    args = parser.parse_args(argv)
    try:
        defaults = SoftArmPlantParams()
        noise = ((defaults.noise_center_px, defaults.noise_radius_px) if args.noise_px is None
                 else args.noise_px)
        plant = SoftArmPlantParams(
            noise_center_px=noise[0], noise_radius_px=noise[1],
            valve_delay=defaults.valve_delay if args.valve_delay is None else args.valve_delay)
        experiment = run_experiment(args.trials, args.duration,
                                    measurement='camera' if args.camera else 'plant',
                                    plant_params=plant, seed=args.seed)
        reference = reference_experiment(args.trials, args.duration)
    except ValueError as error:
        parser.error(str(error))
    paths = write_outputs(experiment, args.out, reference)
    sys.stdout.write(summary_markdown(experiment, reference))
    sys.stdout.write('\n'.join(f'wrote {p}' for p in paths) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
