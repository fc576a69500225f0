"""The alert region's repulsion on the simulated soft arm: a Fig 12 of ``001_b59ad71c956a1751``.

Section 4.3.2: "The SRA's end entered the alert region of the obstacle during 20-25 s, and there
was no contact with the obstacle. The control algorithm adopted the repulsive effect to keep the
SRA's end out of the alert region." Here the paper's scenario (section 4.3.1) is planned with an
alert margin tighter than the one the controller keeps (by default 20 mm against 30 mm), so
that the planned path runs inside the controller's alert region round the obstacle's near edge
and the end is led into it; the path follower (`inflarm_control.path_following`, the
``pressure_controller``'s) follows the path on the simulated plant
(`inflarm_hw.sra_plant.SoftArmPlant`, valves 0.1 s late, measurement noise, one control step of
latency as over DDS), with and without the repulsion, from the demo's start (20 s holding the
start, then the path).

    inflarm-repulsion-figure --out DIR [--gain 1.0] [--plan-margin 0.02] [--alert-margin 0.03]

writes ``DIR/fig12_repulsion.png`` (distance from the true end to the obstacle surface and the
end's depth in the alert region against time, with and without the repulsion, the planned path's
and the border) and ``DIR/summary.md``. It lives here, not in ``inflarm-plan-figures``, because
it joins the simulator (``inflarm_hw``) and the controller (``inflarm_control``), which the
planning package may not import. Matplotlib (Agg) is imported only to draw.
"""

import argparse
from dataclasses import dataclass
from pathlib import Path
import sys
import tempfile

import numpy as np
import numpy.typing as npt

from inflarm_bringup.knowledge_cli import knowledge_plant
from inflarm_control.knowledge import KnowledgeGrid, build_knowledge_database, holding_pressure
from inflarm_control.path_following import PathFollower, PathFollowingParams, project_on_polyline
from inflarm_hw.sra_plant import NOISE_FREE, SoftArmPlant, SoftArmPlantParams
from inflarm_model.alert_regions import grow_boxes, repulsive_offset
from inflarm_planning.collision import box_array, distance_to_boxes
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
from inflarm_planning.trajectory import plan_trajectory

DT = 0.2
"""Control period [s] (the paper's 5 Hz)."""

PLAN_MARGIN = 0.020
"""Alert margin the path is planned with [m]: 10 mm tighter than the controller's."""

HOLD_STEPS = 100
"""Steps holding the start before the path (20 s, as the demo settles)."""

MAX_STEPS = 1000
"""Longest run on the path [steps] (200 s)."""

KNOWLEDGE_GRID = KnowledgeGrid(origin=(-0.01, -0.01, 0.71), spacing=0.01, shape=(16, 16, 3))
"""The knowledge database's points for the path's z range 710-730 mm (the scenario test's)."""


@dataclass(frozen=True)
class RepulsionRun:
    """One run along the path.

    Attributes
    ----------
    times : ndarray, shape (N,)
        From the path's start [s].
    truth, measured : ndarray, shape (N, 3)
        True and measured end points [m].
    reference : ndarray, shape (N, 3)
        The follower's reference on the path at each step [m].
    path : ndarray, shape (M, 3)
        The planned path [m].
    regions : ndarray, shape (1, 2, 3)
        The controller's alert region [m].
    gain : float
        The repulsion gain.
    """

    times: npt.NDArray[np.float64]
    truth: npt.NDArray[np.float64]
    measured: npt.NDArray[np.float64]
    reference: npt.NDArray[np.float64]
    path: npt.NDArray[np.float64]
    regions: npt.NDArray[np.float64]
    gain: float

    @property
    def depth(self) -> npt.NDArray[np.float64]:
        """Depth of the true end in the alert region [m] (0 outside), shape (N,)."""
        return np.linalg.norm(repulsive_offset(self.truth, self.regions), axis=-1)

    @property
    def clearance(self) -> npt.NDArray[np.float64]:
        """Distance from the true end to the obstacle's surface [m], shape (N,)."""
        return distance_to_boxes(self.truth, box_array([OBSTACLE]))

    @property
    def path_error(self) -> npt.NDArray[np.float64]:
        """Distance from the true end to the path [m], shape (N,)."""
        return project_on_polyline(self.truth, self.path)[0]

    @property
    def exit_delay(self) -> float:
        """How long after the reference's last step in the alert region the true end's last
        one came [s] (negative: before it)."""
        def last(points):
            inside = np.flatnonzero(path_depth(points, self.regions) > 0.0)
            return float(self.times[inside[-1]]) if len(inside) else 0.0
        return last(self.truth) - last(self.reference)

    @property
    def finished(self) -> bool:
        """Whether the end reached the goal (within 2 mm) before `MAX_STEPS`."""
        return bool(np.linalg.norm(self.truth[-1] - self.path[-1]) < 0.002)


def path_depth(path: npt.ArrayLike, regions: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Depth of points of the planned path in the alert regions [m], shape (M,)."""
    return np.linalg.norm(repulsive_offset(path, regions), axis=-1)


def scenario_path(plan_margin: float = PLAN_MARGIN) -> npt.NDArray[np.float64]:
    """The paper's scenario planned at 5 mm with ``plan_margin`` [m]: the trajectory's points."""
    return np.asarray(plan_trajectory(START, GOAL, [OBSTACLE], 0.005, plan_margin)
                      .trajectory.points)


def feedforward_along(path: npt.ArrayLike, directory: str | Path | None = None
                      ) -> npt.NDArray[np.float64]:
    """Holding pressures at the waypoints from a knowledge database learnt on the noise-free
    plant over `KNOWLEDGE_GRID` (about 10 s), shape (M, 5) [Pa]."""
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(directory or tmp) / 'knowledge'
        db = build_knowledge_database(where, KNOWLEDGE_GRID, plant_factory=knowledge_plant,
                                      progress=False)
        try:
            return np.array([holding_pressure(db, w) for w in np.asarray(path)])
        finally:
            db.close()


def follow(path: npt.ArrayLike, feedforward: npt.ArrayLike, gain: float,
           alert_margin: float = ALERT_MARGIN, seed: int = 7, noise: bool = True
           ) -> RepulsionRun:
    """Hold the start for `HOLD_STEPS`, then follow ``path`` with the repulsion ``gain`` from
    the obstacle's alert region of ``alert_margin`` [m], on the plant seeded with ``seed``; the
    commands reach the plant one step late."""
    path = np.asarray(path, dtype=float)
    feedforward = np.asarray(feedforward, dtype=float)
    plant = SoftArmPlant(1, SoftArmPlantParams() if noise else NOISE_FREE,
                         np.random.default_rng(seed))
    plant.reset(START)
    pending = [plant.chamber_pressures[0]]

    def apply(command: np.ndarray) -> None:
        pending.append(command)
        plant.step(pending.pop(0), DT)

    regions = grow_boxes(box_array([OBSTACLE]), alert_margin)
    follower = PathFollower(PathFollowingParams(repulsion_gain=gain))
    follower.set_alert_regions(regions)
    follower.start([START], plant.measure()[0], plant.chamber_pressures[0], feedforward[:1])
    command = plant.chamber_pressures[0]
    for _ in range(HOLD_STEPS):
        command = follower.step(plant.measure()[0], DT)
        apply(command)
    follower.start(path, plant.measure()[0], command, feedforward)
    truth, measured, reference = [], [], []
    while len(truth) < MAX_STEPS:
        y = plant.measure()[0]
        reference.append(follower.reference)
        apply(follower.step(y, DT))
        measured.append(y)
        truth.append(plant.end_point[0].copy())
        if follower.at_end and np.linalg.norm(truth[-1] - path[-1]) < 0.002:
            break
    times = np.arange(1, len(truth) + 1) * DT
    return RepulsionRun(times, np.array(truth), np.array(measured), np.array(reference), path,
                        regions, float(gain))


def stretches(inside: npt.ArrayLike, dt: float = DT) -> list[tuple[float, float]]:
    """The (start, end) times [s] of the runs of True in ``inside`` (sampled every ``dt``, the
    first sample at ``dt``)."""
    flags = np.concatenate([[False], np.asarray(inside, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(flags.astype(int)))
    return [(float(a + 1) * dt, float(b) * dt) for a, b in zip(edges[::2], edges[1::2],
                                                               strict=True)]


def summary(runs: list[RepulsionRun], plan_margin: float, alert_margin: float) -> str:
    """The runs' figures as markdown."""
    mm = 1e3
    path = runs[0].path
    planned = path_depth(path, runs[0].regions)
    lines = [
        "# The alert region's repulsion on the simulated soft arm (001, section 4.3.2)",
        '',
        f"The paper's scenario planned with an alert margin of {plan_margin * mm:g} mm, followed "
        f'with an alert region of {alert_margin * mm:g} mm: the planned path runs up to '
        f'{planned.max() * mm:.1f} mm deep in the region. True end points, 5 Hz, noise '
        f'0.5 mm, one step of latency.',
        '',
        '| repulsion gain | time in the region | stretches | max depth | out after the reference '
        '| min clearance to the obstacle | max distance to the path | time on the path |',
        '| --- | --- | --- | --- | --- | --- | --- | --- |',
    ]
    for run in runs:
        inside = run.depth > 0.0
        spans = stretches(inside)
        span_text = ', '.join(f'{a:.1f}-{b:.1f} s' for a, b in spans[:3]) + (
            ' ...' if len(spans) > 3 else '')
        lines.append(
            f'| {run.gain:g} | {inside.sum() * DT:.1f} s | {span_text or "none"} | '
            f'{run.depth.max() * mm:.1f} mm | {run.exit_delay:.1f} s | '
            f'{run.clearance.min() * mm:.1f} mm | '
            f'{run.path_error.max() * mm:.1f} mm | {run.times[-1]:.0f} s'
            f'{"" if run.finished else " (not finished)"} |')
    lines.append('')
    return '\n'.join(lines)


def plot(runs: list[RepulsionRun], alert_margin: float, path: Path) -> None:
    """Fig 12 analogue: clearance and depth of the true end against time."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    mm = 1e3
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True)
    for run, colour in zip(runs, ('0.5', 'C3', 'C1', 'C4'), strict=False):
        label = f'true end, repulsion gain {run.gain:g}' if run.gain else \
            'true end, no repulsion'
        top.plot(run.times, run.clearance * mm, color=colour, lw=1.2, label=label)
        bottom.plot(run.times, run.depth * mm, color=colour, lw=1.2, label=label)
    reference = runs[-1].reference
    top.plot(runs[-1].times, distance_to_boxes(reference, box_array([OBSTACLE])) * mm, 'k--',
             lw=1.0, label="planned path (the follower's reference)")
    top.axhline(alert_margin * mm, color='C0', label='border of the alert region')
    top.set_ylabel('distance to the obstacle [mm]')
    top.set_ylim(bottom=0.0)
    top.legend(fontsize=7)
    top.grid(alpha=0.3)
    top.set_title('End to obstacle distance with the repulsion (Fig. 12 of 001)')
    bottom.plot(runs[-1].times, path_depth(reference, runs[0].regions) * mm, 'k--', lw=1.0,
                label="planned path (the follower's reference)")
    bottom.set_ylabel('depth in the alert region [mm]')
    bottom.set_xlabel('t [s] (from the start of the path)')
    bottom.grid(alpha=0.3)
    bottom.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--gain', type=float, default=PathFollowingParams().repulsion_gain,
                        help="repulsion gain (default: the follower's)")
    parser.add_argument('--plan-margin', type=float, default=PLAN_MARGIN,
                        help=f'alert margin of the plan [m] (default {PLAN_MARGIN})')
    parser.add_argument('--alert-margin', type=float, default=ALERT_MARGIN,
                        help=f'alert margin of the controller [m] (default {ALERT_MARGIN})')
    parser.add_argument('--seed', type=int, default=7, help='noise seed (default 7)')
    args = parser.parse_args(argv)
    if not (args.gain > 0.0 and 0.0 <= args.plan_margin <= args.alert_margin):
        print('inflarm-repulsion-figure: expected --gain > 0 and 0 <= --plan-margin <= '
              '--alert-margin', file=sys.stderr)
        return 2
    path = scenario_path(args.plan_margin)
    feedforward = feedforward_along(path)
    runs = [follow(path, feedforward, gain, args.alert_margin, args.seed)
            for gain in (0.0, args.gain)]
    args.out.mkdir(parents=True, exist_ok=True)
    plot(runs, args.alert_margin, args.out / 'fig12_repulsion.png')
    text = summary(runs, args.plan_margin, args.alert_margin)
    (args.out / 'summary.md').write_text(text)
    print(text)
    print(f'wrote {args.out / "fig12_repulsion.png"} and {args.out / "summary.md"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
