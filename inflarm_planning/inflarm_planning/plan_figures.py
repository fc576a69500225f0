"""Figures 10 and 12 of 001_b59ad71c956a1751: the planned path around the paper's obstacle.

    inflarm-plan-figures --out DIR [--resolution 0.005] [--alert-margin 0.03]

writes ``DIR/fig10_path.png`` (the obstacle, its alert region, the A* grid path and the
trajectory made from it, with the arm's central axes at a few poses),
``DIR/fig12_distance.png`` (distance from the end to the obstacle surface along the trajectory
against time, with the border of the alert region) and ``DIR/summary.md`` (path lengths with
both costs, clearances, durations and planning times), and prints the summary.

matplotlib (Agg) is imported only when plotting.
"""

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
import time

import numpy as np
import numpy.typing as npt

from inflarm_model.soft_arm import central_axes
from inflarm_planning.astar import plan
from inflarm_planning.collision import box_array, distance_to_boxes
from inflarm_planning.scenario import ACTUATOR_WIDTH, ALERT_MARGIN, GOAL, OBSTACLE, START
from inflarm_planning.trajectory import TrajectoryPlan, plan_trajectory

AXIS_SAMPLES = 200
"""Points per actuator axis when measuring the axes' clearance."""


@dataclass(frozen=True)
class Scenario:
    """Everything Figs 10 and 12 and the summary show, computed once.

    Attributes
    ----------
    planned : TrajectoryPlan
        A* with the default cost and the trajectory made from it.
    paper_length : float
        Length of the grid path with the cost of eq. (7) [m].
    resolution, alert_margin : float
        Grid spacing and alert margin [m].
    planning_time_s : float
        Wall time of the A* search and the trajectory (free-space build excluded) [s].
    """

    planned: TrajectoryPlan
    paper_length: float
    resolution: float
    alert_margin: float
    planning_time_s: float


def end_clearance(points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Distance from end points to the obstacle's surface [m], shape (N,)."""
    return distance_to_boxes(points, box_array([OBSTACLE]))


def axes_clearance(points: npt.ArrayLike) -> float:
    """Smallest distance from the PEA axes to the obstacle over the given end points [m]."""
    axes = central_axes(np.asarray(points))  # (N, 2, 2, 3)
    t = np.linspace(0.0, 1.0, AXIS_SAMPLES)[:, None]
    samples = axes[..., None, 0, :] + t * (axes[..., None, 1, :] - axes[..., None, 0, :])
    return float(distance_to_boxes(samples.reshape(-1, 3), box_array([OBSTACLE])).min())


def run_scenario(resolution: float = 0.005, alert_margin: float = ALERT_MARGIN) -> Scenario:
    """Plan the paper's scenario (section 4.3.1) with both costs."""
    plan_trajectory(START, GOAL, [OBSTACLE], resolution, alert_margin)  # build the free space
    started = time.perf_counter()
    planned = plan_trajectory(START, GOAL, [OBSTACLE], resolution, alert_margin)
    elapsed = time.perf_counter() - started
    paper = plan(START, GOAL, [OBSTACLE], resolution, alert_margin, cost='paper')
    return Scenario(planned, paper.length, resolution, alert_margin, elapsed)


def _box_faces(low: npt.ArrayLike, high: npt.ArrayLike) -> list[np.ndarray]:
    (x0, y0, z0), (x1, y1, z1) = low, high
    corners = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                        [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    faces = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 3, 7, 4)]
    return [corners[list(f)] for f in faces]


def plot_fig10(scenario: Scenario, path: Path, poses: int = 5) -> None:
    """Fig. 10: the obstacle, its alert region and the planned path, in mm."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    mm = 1e3
    grid = scenario.planned.grid.path * mm
    trajectory = scenario.planned.trajectory.points * mm
    fig = plt.figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot(projection='3d')
    ax.computed_zorder = False  # draw the path over the translucent box
    obstacle = box_array([OBSTACLE])[0] * mm
    alert = box_array([OBSTACLE], scenario.alert_margin)[0] * mm
    ax.add_collection3d(Poly3DCollection(_box_faces(*alert), facecolor='none', alpha=0.6,
                                         edgecolor='C0', linewidth=0.6, linestyle='--',
                                         zorder=1))
    ax.add_collection3d(Poly3DCollection(_box_faces(*obstacle), facecolor='#a0522d', alpha=0.45,
                                         edgecolor='#5a2d0c', linewidth=0.6, zorder=2))
    for n in np.linspace(0, len(trajectory) - 1, poses).round().astype(int):
        axes = central_axes(trajectory[n] / mm) * mm
        t = np.linspace(0.0, 1.0, 200)[:, None]
        for a, b in axes:  # sampled, so that the part above the plotted box is clipped off
            ax.plot(*(a + t * (b - a)).T, color='C2', lw=1.0, alpha=0.8, zorder=3,
                    axlim_clip=True)
    ax.plot([], [], color='C2', lw=1.0, label='PEA1 / PEA2 central axes')
    ax.plot([], [], color='C0', lw=0.6, ls='--',
            label=f'alert region ({scenario.alert_margin * mm:g} mm)')
    ax.plot(*grid.T, color='0.45', lw=1.0, zorder=4,
            label=f'A* grid path ({scenario.resolution * mm:g} mm)')
    ax.plot(*trajectory.T, 'k', lw=2.0, zorder=5, label='trajectory (shortcut, smoothed)')
    ax.scatter(*trajectory[0], color='C2', s=30, zorder=6, label='start')
    ax.scatter(*trajectory[-1], color='C1', s=30, zorder=6, label='goal')
    ax.set_xlim(-20, 200)
    ax.set_ylim(-20, 200)
    ax.set_zlim(820, 580)  # z grows away from the mount, as the arm hangs: the mount is above
    ax.set_box_aspect((220, 220, 240))
    ax.set_xlabel('x [mm]')
    ax.set_ylabel('y [mm]')
    ax.set_zlabel('z [mm]')
    ax.view_init(elev=20, azim=-150)
    ax.set_title('Obstacle avoidance path (Fig. 10)')
    ax.legend(loc='upper left', fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def plot_fig12(scenario: Scenario, path: Path) -> None:
    """Fig. 12: distance from the end to the obstacle surface against time."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    trajectory = scenario.planned.trajectory
    distance = end_clearance(trajectory.points) * 1e3
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    ax.plot(trajectory.times, distance, 'k', label='planned trajectory')
    ax.axhline(scenario.alert_margin * 1e3, color='C0', label='border of the alert region')
    ax.set_xlabel('t [s]')
    ax.set_ylabel('distance to the obstacle surface [mm]')
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title('End to obstacle distance (Fig. 12)')
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def summary(scenario: Scenario) -> str:
    """The scenario's figures as markdown."""
    planned = scenario.planned
    grid, trajectory = planned.grid, planned.trajectory
    mm = 1e3
    straight = float(np.linalg.norm(np.subtract(GOAL, START)))
    rows = [
        ('straight line start to goal', f'{straight * mm:.1f} mm'),
        ("grid path, cost 'length' (default)", f'{grid.length * mm:.1f} mm'),
        ("grid path, cost 'paper' (eq. 7)", f'{scenario.paper_length * mm:.1f} mm'),
        ('trajectory (shortcut, smoothed)', f'{trajectory.length * mm:.1f} mm, '
                                           f'{len(trajectory.points)} waypoints, '
                                           f'{trajectory.duration:.1f} s'),
        ('end to obstacle, grid path (min)', f'{end_clearance(grid.path).min() * mm:.1f} mm'),
        ('end to obstacle, trajectory (min)',
         f'{end_clearance(trajectory.points).min() * mm:.1f} mm'),
        ('PEA axes to obstacle, trajectory (min)',
         f'{axes_clearance(trajectory.points) * mm:.1f} mm'),
        ('cells expanded', f'{grid.expanded}'),
        ('free-space build', f'{grid.free_space.build_time_s * mm:.0f} ms'),
        ('A* + trajectory', f'{scenario.planning_time_s * mm:.0f} ms'),
    ]
    lines = [
        "# Path planning on the paper's scenario (001, section 4.3.1)",
        '',
        f'Start {np.multiply(START, mm).round(1).tolist()} mm, goal '
        f'{np.multiply(GOAL, mm).round(1).tolist()} mm, obstacle x 35-140, y 40-140, '
        f'z 650-780 mm; resolution {scenario.resolution * mm:g} mm, alert margin '
        f'{scenario.alert_margin * mm:g} mm (node default: half the assumed '
        f'{ACTUATOR_WIDTH * mm:g} mm actuator width + 5 mm tracking error).',
        '',
        '| quantity | value |',
        '| --- | --- |',
        *(f'| {name} | {value} |' for name, value in rows),
        '',
    ]
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--resolution', type=float, default=0.005, help='grid spacing [m]')
    parser.add_argument('--alert-margin', type=float, default=ALERT_MARGIN,
                        help=f'alert margin [m] (default {ALERT_MARGIN})')
    args = parser.parse_args(argv)
    scenario = run_scenario(args.resolution, args.alert_margin)
    args.out.mkdir(parents=True, exist_ok=True)
    plot_fig10(scenario, args.out / 'fig10_path.png')
    plot_fig12(scenario, args.out / 'fig12_distance.png')
    text = summary(scenario)
    (args.out / 'summary.md').write_text(text)
    print(text)
    print(f'wrote {args.out / "fig10_path.png"}, {args.out / "fig12_distance.png"} and '
          f'{args.out / "summary.md"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
