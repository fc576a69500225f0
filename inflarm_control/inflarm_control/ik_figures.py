"""Figures 10 and 11 of 000_ce37cf035a0a87c6: elastostatic IK along a straight tip path.

    python -m inflarm_control.ik_figures --out DIR [--samples 500] [--duration 5.0]
        [--gain 50.0] [--method paper|effective]

writes ``DIR/fig10_configurations.png`` (the deflected arm along the path, links drawn through
the DH frame origins of ``FlexibleArm.joint_origins``) and ``DIR/fig11_motor_angles.png``
(motor angles against time, elastostatic vs rigid IK), and prints the largest link moment, the
inflation pressure it needs (eq. 3) and how far the rigid-IK angles miss on the deflecting arm.

The paper does not give x_start and x_d. We take a path in front of the arm, across the
shoulder, rising: x_start = (0.6, -0.5, 0.2) m to x_d = (0.7, 0.5, 0.6) m (tip 0.81-1.05 m
from the base, within the reach 2L = 1.2 m and away from the folded-elbow and first-axis
singularities), with the paper's load f_e = (0, 10, -15) N and k = 172.71 N·m/rad. It loads
link 1 up to ~17.4 N·m, the order of the paper's 17.51 N·m.

matplotlib (Agg) is imported only when plotting.
"""

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from inflarm_control.elastostatic_ik import (
    PressureRequirement,
    TrackingResult,
    minimum_pressure_along,
    solve_ik,
    solve_rigid_ik,
    straight_line_trajectory,
    track_trajectory,
)
from inflarm_model.elastostatics import spring_deflections
from inflarm_model.kinematics import FlexibleArm, RigidArm
from inflarm_model.link import LINK_RADIUS, MEAN_STIFFNESS

X_START = (0.6, -0.5, 0.2)  # [m], our choice (the paper gives none)
X_GOAL = (0.7, 0.5, 0.6)  # [m]
PAPER_FORCE = (0.0, 10.0, -15.0)  # f_e [N], section 4
START_GUESS = (0.0, 0.6, -1.2)  # elbow-up branch for the first waypoint [rad]


@dataclass(frozen=True)
class IkScenario:
    """Everything Figs 10-11 show, computed once.

    Attributes
    ----------
    flexible : TrackingResult
        Elastostatic IK (eq. 9) along the path.
    rigid_q_m : ndarray, shape (N, 3)
        Rigid-arm IK (Table 1) of every waypoint [rad].
    rigid_tip : ndarray, shape (N, 3)
        Where the deflecting arm's tip actually goes with the rigid angles [m].
    x_d : ndarray, shape (N, 3)
        The planned path [m].
    pressure : PressureRequirement
        Largest link moment along the elastostatic trajectory and the pressure it needs.
    """

    flexible: TrackingResult
    rigid_q_m: npt.NDArray[np.float64]
    rigid_tip: npt.NDArray[np.float64]
    x_d: npt.NDArray[np.float64]
    pressure: PressureRequirement


def run_scenario(
    samples: int = 500,
    duration: float = 5.0,
    gain: float = 50.0,
    method: str = 'paper',
    x_start: Sequence[float] = X_START,
    x_goal: Sequence[float] = X_GOAL,
    force: Sequence[float] = PAPER_FORCE,
    stiffness: float = MEAN_STIFFNESS,
) -> IkScenario:
    """Elastostatic and rigid IK along the straight path x_start -> x_goal (section 4).

    Parameters
    ----------
    samples : int
        Waypoints, >= 2.
    duration : float
        Duration of the path [s].
    gain : float
        K of eq. (9) [1/s].
    method : {'paper', 'effective'}
        Velocity map of ``track_trajectory``.
    x_start, x_goal : sequence of 3 float
        End points [m], base frame.
    force : sequence of 3 float
        Tip load f_e [N], base frame.
    stiffness : float
        Spring stiffness k [N·m/rad].

    Returns
    -------
    IkScenario
    """
    arm, rigid = FlexibleArm(), RigidArm()
    times, x_d, v_d = straight_line_trajectory(x_start, x_goal, duration, samples)
    q_m0 = solve_ik(arm, x_d[0], force, stiffness, np.array(START_GUESS))
    flexible = track_trajectory(arm, times, x_d, v_d, force, stiffness, q_m0, gain,
                                method=method)
    rigid_q_m = np.empty((samples, 3))
    reference = flexible.q_m[0]
    for n, x in enumerate(x_d):
        rigid_q_m[n] = reference = solve_rigid_ik(rigid, x, reference)
    rigid_tip = spring_deflections(arm, rigid_q_m, force, stiffness).tip_position
    pressure = minimum_pressure_along(arm, flexible.q, force, stiffness, LINK_RADIUS)
    return IkScenario(flexible, rigid_q_m, rigid_tip, x_d, pressure)


def plot_fig10(scenario: IkScenario, path: Path, frames: int = 7) -> None:
    """Fig. 10: deflected configurations along the path, drawn through the DH frame origins."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    arm = FlexibleArm()
    fig = plt.figure(figsize=(7.0, 6.0))
    ax = fig.add_subplot(projection='3d')
    x_d = scenario.x_d
    ax.plot(*x_d.T, 'k--', lw=1.0, label='planned path')
    ax.plot(*scenario.flexible.tip_position.T, 'C0', lw=1.5, label='deflected tip (elastostatic)')
    ax.plot(*scenario.rigid_tip.T, 'C3', lw=1.0, label='deflected tip (rigid IK angles)')
    for n in np.linspace(0, len(x_d) - 1, frames).round().astype(int):
        origins = arm.joint_origins(scenario.flexible.q[n])
        ax.plot(*origins.T, 'o-', color='0.35', ms=2.5, lw=2.0, alpha=0.8)
    ax.scatter(*x_d[0], color='C2', s=30, label='x_start')
    ax.scatter(*x_d[-1], color='C1', s=30, label='x_d')
    points = np.vstack([x_d, scenario.rigid_tip, np.zeros((1, 3))])
    ax.set_box_aspect(np.ptp(points, axis=0) + 0.05)  # metres look like metres on every axis
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_zlabel('z [m]')
    ax.set_title('Elastostatic IK, f_e = (0, 10, -15) N, k = 172.71 N·m/rad')
    ax.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def plot_fig11(scenario: IkScenario, path: Path) -> None:
    """Fig. 11: motor angles against time, elastostatic (flexible) vs rigid IK."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    t = scenario.flexible.times
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(6.5, 6.5))
    for i, (ax, name) in enumerate(zip(axes, ('theta_1', 'theta_2', 'theta_5'), strict=True)):
        ax.plot(t, np.degrees(scenario.flexible.q_m[:, i]), 'C0', label='flexible links')
        ax.plot(t, np.degrees(scenario.rigid_q_m[:, i]), 'C3--', label='rigid links')
        ax.set_ylabel(f'{name} [deg]')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel('t [s]')
    fig.suptitle('Motor joint set points')
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--samples', type=int, default=500, help='waypoints (default 500)')
    parser.add_argument('--duration', type=float, default=5.0, help='path duration [s]')
    parser.add_argument('--gain', type=float, default=50.0, help='K of eq. (9) [1/s]')
    parser.add_argument('--method', choices=('paper', 'effective'), default='paper',
                        help='velocity map of eq. (9) (default: paper, J_m^#)')
    args = parser.parse_args(argv)
    scenario = run_scenario(args.samples, args.duration, args.gain, args.method)
    args.out.mkdir(parents=True, exist_ok=True)
    plot_fig10(scenario, args.out / 'fig10_configurations.png')
    plot_fig11(scenario, args.out / 'fig11_motor_angles.png')
    p = scenario.pressure
    lowest = ('none of the tested pressures' if p.lowest_sufficient_pressure is None
              else f'{p.lowest_sufficient_pressure / 1e3:.0f} kPa')
    miss = np.linalg.norm(scenario.rigid_tip - scenario.x_d, axis=1)
    print(f'max link moment: {p.max_moment:.2f} N·m on link {p.link} (waypoint {p.index})')
    print(f'required pressure: {p.required_pressure / 1e3:.1f} kPa (eq. 3, r = '
          f'{LINK_RADIUS * 1e3:.0f} mm); lowest tested pressure that holds it: {lowest}')
    print(f'elastostatic IK tip error: max {scenario.flexible.tip_error.max() * 1e3:.3f} mm, '
          f'final {scenario.flexible.tip_error[-1] * 1e3:.4f} mm')
    print(f'rigid IK angles on the deflecting arm miss by {miss.min() * 1e3:.1f}-'
          f'{miss.max() * 1e3:.1f} mm (at x_d: {miss[-1] * 1e3:.1f} mm)')
    print(f'wrote {args.out / "fig10_configurations.png"} and '
          f'{args.out / "fig11_motor_angles.png"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
