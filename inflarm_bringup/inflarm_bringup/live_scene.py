"""The live view's scene: both arms, their plans and the camera in a viser web page, with controls.

The core of the ``live_view`` node (``inflarm_bringup.nodes.live_view``), without rclpy: plain
numpy data and inflarm messages in, viser scene and GUI elements out. The node stores the latest
message of each topic and calls `LiveScene`'s ``draw_*`` methods from a timer; a method
resends only what changed, so an idle system costs no traffic.

World (the viewer's fixed frame): the frames of `inflarm_bringup.systems.STATIC_FRAMES`, as in
RViz: the inflatable arm's ``base_link`` at the origin, the soft arm's ``sra_mount`` beside it,
hanging (its z axis down). Everything of an arm is drawn in its own frame.

- `RobotModel`: the arm's URDF (``robot_description``, springs included) as Pinocchio's model
  for the link frames plus the URDF's cylinder visuals, each assigned to the inflated link it is
  part of (for its wrinkling colour);
- `margin_colour`: green to red as a link's wrinkling margin runs out;
- `ScrollingPlot`: samples of the last ``window_s`` seconds for a uPlot chart;
- `start_server`: a viser server on exactly ``host:port`` (viser itself would quietly take the
  next free port);
- `LiveScene`: the scene, the plots, the camera panel and the controls.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
import contextlib
from dataclasses import dataclass
import io
import math
import threading
import xml.etree.ElementTree as ET

import numpy as np
import numpy.typing as npt

from inflarm_bringup.systems import STATIC_FRAMES
from inflarm_control.path_following import project_on_polyline
from inflarm_model.soft_arm import CHAMBERS, central_axes
from inflarm_model.urdf import BASE_LINK, SPRING_JOINT_NAMES, TIP_LINK
from inflarm_msgs_json import ObstacleSet

#: The inflated link that each motor joint carries (000, section 2: joint_2 at link_1's root,
#: joint_3 at link_2's); a visual belongs to the link of the nearest such joint above it.
INFLATED_LINKS = {'joint_2': 'link_1', 'joint_3': 'link_2'}
SRA_FRAME = 'sra_mount'

BALL_COLOUR = (255, 214, 0)  # the yellow ball
PATH_COLOUR = (0, 150, 255)  # the planned path
TRUTH_COLOUR = (40, 200, 60)  # true end point / true tip
ESTIMATE_COLOUR = (230, 50, 230)  # estimated tip and load
OBSTACLE_COLOUR = (220, 40, 40)
ALERT_COLOUR = (255, 150, 0)
AXIS_COLOUR = (90, 90, 110)
GHOST_COLOUR = (150, 150, 170)
TRAJECTORY_COLOUR = (255, 120, 0)
FABRIC_COLOUR = (225, 225, 210)
FORCE_SCALE_M_PER_N = 0.01  # the load arrow: 1 cm per newton


@dataclass(frozen=True)
class Visual:
    """A cylinder of the URDF posed in the arm's base frame.

    Attributes
    ----------
    name : str
        ``<URDF link>/<index>``.
    link : str
        The inflated link it is part of (`INFLATED_LINKS`), or '' for none.
    pose : ndarray, shape (4, 4)
        Cylinder frame in ``base_link`` (the cylinder along its z axis, centred) [m].
    radius, length : float
        [m].
    """

    name: str
    link: str
    pose: npt.NDArray[np.float64]
    radius: float
    length: float


def _origin(element: ET.Element | None) -> npt.NDArray[np.float64]:
    """The 4x4 transform of a URDF ``<origin xyz rpy>`` (identity when absent)."""
    import pinocchio as pin

    pose = np.eye(4)
    if element is None:
        return pose
    xyz = [float(v) for v in element.get('xyz', '0 0 0').split()]
    rpy = [float(v) for v in element.get('rpy', '0 0 0').split()]
    if len(xyz) != 3 or len(rpy) != 3:
        raise ValueError(f'origin: expected xyz and rpy of 3 numbers, got {element.attrib}')
    pose[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    pose[:3, 3] = xyz
    return pose


class RobotModel:
    """The inflatable arm of a URDF: link frames (Pinocchio) and cylinder visuals.

    Parameters
    ----------
    urdf : str
        The URDF text, as ``robot_description`` publishes it.

    Raises
    ------
    ValueError
        If the text is not a URDF Pinocchio can build a model from, or lacks ``tip``.
    """

    def __init__(self, urdf: str) -> None:
        import pinocchio as pin

        try:
            root = ET.fromstring(urdf)
        except ET.ParseError as error:
            raise ValueError(f'robot_description: not XML ({error})') from None
        if root.tag != 'robot':
            raise ValueError(f'robot_description: expected a <robot> URDF, got <{root.tag}>')
        try:
            self.model = pin.buildModelFromXML(urdf)
        except (RuntimeError, ValueError) as error:
            raise ValueError(f'robot_description: not a URDF Pinocchio can read ({error})'
                             ) from None
        self.data = self.model.createData()
        if not self.model.existFrame(TIP_LINK):
            raise ValueError(f"robot_description: no link '{TIP_LINK}'")
        self.joint_names = tuple(self.model.names[1:])
        self._visuals: list[tuple[int, str, npt.NDArray[np.float64], float, float, str]] = []
        for link in root.iter('link'):
            name = link.get('name', '')
            if not self.model.existFrame(name):
                continue
            frame = self.model.getFrameId(name)
            for index, visual in enumerate(link.findall('visual')):
                cylinder = visual.find('geometry/cylinder')
                if cylinder is None:
                    continue  # only cylinders are drawn: the generated URDF has no others
                radius, length = float(cylinder.get('radius')), float(cylinder.get('length'))
                self._visuals.append((frame, f'{name}/{index}', _origin(visual.find('origin')),
                                      radius, length, self._inflated_link(frame)))
        #: visual name -> the inflated link it is part of ('' for none)
        self.visual_links = {v[1]: v[5] for v in self._visuals}

    def _inflated_link(self, frame: int) -> str:
        joint = self.model.frames[frame].parentJoint
        while joint > 0:
            if self.model.names[joint] in INFLATED_LINKS:
                return INFLATED_LINKS[self.model.names[joint]]
            joint = self.model.parents[joint]
        return ''

    def configuration(self, positions: Mapping[str, float]) -> npt.NDArray[np.float64]:
        """Pinocchio's q from joint positions by name (joints not given at 0) [rad]."""
        import pinocchio as pin

        q = pin.neutral(self.model)
        for name, value in positions.items():
            if not self.model.existJointName(name):
                continue
            joint = self.model.joints[self.model.getJointId(name)]
            if joint.nq == 1:
                q[joint.idx_q] = value
            elif joint.nq == 2:  # continuous: cos, sin
                q[joint.idx_q:joint.idx_q + 2] = math.cos(value), math.sin(value)
        return q

    def poses(self, positions: Mapping[str, float]) -> tuple[list[Visual],
                                                             npt.NDArray[np.float64]]:
        """The visuals and the ``tip`` frame posed at ``positions`` (by joint name) [m].

        Returns
        -------
        visuals : list of Visual
        tip : ndarray, shape (4, 4)
            The tip frame in ``base_link``.
        """
        import pinocchio as pin

        values = np.array([float(v) for v in positions.values()])
        if not np.isfinite(values).all():
            raise ValueError(f'expected finite joint positions, got {dict(positions)}')
        pin.framesForwardKinematics(self.model, self.data, self.configuration(positions))
        visuals = [Visual(name, link, self.data.oMf[frame].homogeneous @ origin, radius, length)
                   for frame, name, origin, radius, length, link in self._visuals]
        return visuals, self.data.oMf[self.model.getFrameId(TIP_LINK)].homogeneous.copy()


def rigid_positions(positions: Mapping[str, float]) -> dict[str, float]:
    """The same motor angles with every virtual spring undeflected: the rigid arm."""
    return {name: 0.0 if name in SPRING_JOINT_NAMES else float(value)
            for name, value in positions.items()}


def margin_colour(margin: float, wrinkling_moment: float) -> tuple[int, int, int]:
    """Green with half the wrinkling moment or more to spare, through yellow, to red at
    wrinkling (margin <= 0); 8-bit RGB."""
    share = 0.0 if wrinkling_moment <= 0.0 else margin / wrinkling_moment
    s = min(max(share / 0.5, 0.0), 1.0)  # 0: wrinkled, 1: half the moment to spare
    if s >= 0.5:
        return (int(round(460 * (1.0 - s))), 200, 40)
    return (230, int(round(400 * s)), 40)


def obstacle_boxes(obstacles: ObstacleSet) -> list[tuple[str, npt.NDArray[np.float64],
                                                         npt.NDArray[np.float64], bool]]:
    """(name, centre (3,), size (3,), is alert region) of each obstacle and its alert region,
    grown by ``alert_margin`` on every side [m]."""
    boxes = []
    for index, cuboid in enumerate(obstacles.obstacles):
        low, high = np.asarray(cuboid.min), np.asarray(cuboid.max)
        boxes.append((f'obstacle_{index}', (low + high) / 2, high - low, False))
        if obstacles.alert_margin > 0.0:
            boxes.append((f'alert_{index}', (low + high) / 2,
                          high - low + 2 * obstacles.alert_margin, True))
    return boxes


def path_distance(point: npt.ArrayLike, path: npt.ArrayLike) -> float:
    """Distance of a point to a polyline (a single point: to it) [m]."""
    path = np.asarray(path, dtype=float).reshape(-1, 3)
    p = np.asarray(point, dtype=float).reshape(1, 3)
    if len(path) == 1:
        return float(np.linalg.norm(p[0] - path[0]))
    return float(project_on_polyline(p, path)[0][0])


class ScrollingPlot:
    """Samples of some series over the last ``window_s`` seconds, for a uPlot chart.

    Parameters
    ----------
    labels : sequence of str
        Series names.
    window_s : float
        Time kept [s].
    """

    def __init__(self, labels: Sequence[str], window_s: float = 30.0) -> None:
        if window_s <= 0.0:
            raise ValueError(f'expected window_s > 0 [s], got {window_s}')
        self.labels = tuple(labels)
        self.window_s = float(window_s)
        self._samples: deque[tuple[float, tuple[float, ...]]] = deque()

    def add(self, t: float, values: Sequence[float]) -> None:
        """One sample of every series at time ``t`` [s] (NaN where a series has none)."""
        if len(values) != len(self.labels):
            raise ValueError(f'expected {len(self.labels)} values, got {len(values)}')
        self._samples.append((float(t), tuple(float(v) for v in values)))
        while self._samples and self._samples[0][0] < t - self.window_s:
            self._samples.popleft()

    def __len__(self) -> int:
        return len(self._samples)

    def arrays(self, now: float) -> tuple[npt.NDArray[np.float64], ...]:
        """(time relative to ``now`` [s], one array per series): uPlot's data layout. A NaN is
        held from the series' previous value (uPlot cannot draw NaN), 0 before any."""
        if not self._samples:
            return (np.zeros(0),) + tuple(np.zeros(0) for _ in self.labels)
        t = np.array([s[0] for s in self._samples]) - now
        values = np.array([s[1] for s in self._samples]).reshape(len(t), len(self.labels))
        for column in values.T:
            valid = np.isfinite(column)
            if not valid.any():
                column[:] = 0.0
                continue
            index = np.where(valid, np.arange(len(column)), 0)
            np.maximum.accumulate(index, out=index)
            column[:] = np.where(valid[index], column[index], column[valid][0])
        return (t,) + tuple(values.T.copy())


def mark_ball(rgb: npt.NDArray[np.uint8], camera, camera2mount, ball: npt.ArrayLike,
              diameter: float) -> npt.NDArray[np.uint8]:
    """A copy of a camera image with the measured ball drawn on it: its outline as the camera
    sees a sphere of ``diameter`` [m] at ``ball`` (``sra_mount``) and a cross at its centre.

    ``camera`` is an `inflarm_model.camera.PinholeCamera`, ``camera2mount`` the camera's pose
    (an `inflarm_model.camera.RigidTransform`). The image is returned unmarked when the ball is
    behind the camera.
    """
    import cv2

    from inflarm_model.camera import project_points, sphere_image

    out = np.ascontiguousarray(rgb, dtype=np.uint8).copy()
    centre = camera2mount.inverse().apply(np.asarray(ball, dtype=float).reshape(1, 3))[0]
    if centre[2] <= diameter:
        return out
    outline = sphere_image(camera, centre, diameter / 2, 64).outline
    cv2.polylines(out, [np.round(outline).astype(np.int32)], True, (255, 0, 255), 2)
    u, v = np.round(project_points(camera, centre[None])[0]).astype(int)
    cv2.drawMarker(out, (int(u), int(v)), (255, 0, 255), cv2.MARKER_CROSS, 14, 2)
    return out


class PortInUseError(ValueError):
    """The view's port is taken by another program."""


def start_server(host: str, port: int):
    """A viser server on exactly ``host:port`` (0: any free port).

    Raises
    ------
    PortInUseError
        If the port is taken (viser would move to the next free one: a URL nobody expects).
    """
    import viser

    with contextlib.redirect_stdout(io.StringIO()):  # its banner; the node logs the URL
        server = viser.ViserServer(host=host, port=port, verbose=False)
    if port and server.get_port() != port:
        taken = server.get_port()
        server.stop()
        raise PortInUseError(f'port {port} on {host} is in use (the next free one would be '
                             f'{taken}): stop what holds it, or set the parameter port')
    return server


def _wxyz(rotation: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A rotation matrix as a unit quaternion (w, x, y, z)."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(np.asarray(rotation, dtype=float)[:3, :3]).as_quat()
    return np.array([w, x, y, z])


@dataclass
class Controls:
    """What the page's controls do: each callback gets the point in its arm's frame [m]."""

    plan_to: Callable[[npt.NDArray[np.float64]], str]  # soft-arm goal -> status text
    start_trial: Callable[[npt.NDArray[np.float64]], str]
    vent: Callable[[], str]
    tip_target: Callable[[npt.NDArray[np.float64]], str]


class LiveScene:
    """Both arms in a viser server: the scene, the plots, the camera panel and the controls.

    Parameters
    ----------
    server : viser.ViserServer
    controls : Controls
    controls_enabled : bool
        False: the controls are shown disabled, with the reason (they would move an arm).
    goal : array-like, shape (3,)
        Initial soft-arm goal in ``sra_mount`` [m].
    tip_target : array-like, shape (3,)
        Initial tip target in ``base_link`` [m].
    history_s : float
        Plot window [s].
    """

    def __init__(self, server, controls: Controls, controls_enabled: bool,
                 goal: npt.ArrayLike, tip_target: npt.ArrayLike, history_s: float = 30.0,
                 disabled_reason: str = '') -> None:
        import viser.uplot as uplot

        self.server = server
        self.controls = controls
        self.controls_enabled = controls_enabled
        self._lock = threading.Lock()
        self._last: dict[str, object] = {}  # what each element shows, to resend only changes
        self._robot: RobotModel | None = None
        scene = server.scene
        scene.set_up_direction('+z')
        server.initial_camera.position = (1.75, -1.45, 1.3)
        server.initial_camera.look_at = (0.95, 0.1, 0.6)
        scene.add_grid('/grid', width=4.0, height=4.0, cell_size=0.1, position=(0.6, 0.0, 0.0))
        for parent, child, xyz, (qx, qy, qz, qw) in STATIC_FRAMES:
            if parent == 'world':
                scene.add_frame(f'/{child}', wxyz=(qw, qx, qy, qz), position=xyz,
                                axes_length=0.1, axes_radius=0.004)
        scene.add_label(f'/{BASE_LINK}/label', 'inflatable arm (base_link)',
                        position=(0.0, 0.0, -0.08))
        scene.add_label(f'/{SRA_FRAME}/label', 'soft arm (sra_mount)', position=(0.0, 0.0, -0.06))

        gui = server.gui
        gui.configure_theme(control_width='large', show_logo=False)
        self.status = gui.add_markdown('**inflarm live view**: waiting for data')
        with gui.add_folder('Controls'):
            note = ('Controls are **enabled**: they command the running system.'
                    if controls_enabled else
                    '**Controls are disabled**: they would command the robot. '
                    + (disabled_reason or 'Start the view with `controls_enabled:=true` '
                       'to enable them.'))
            gui.add_markdown(note)
            self.goal_button = gui.add_button('Plan path to goal', disabled=not controls_enabled)
            self.trial_button = gui.add_button('Start pid_ilc trial to goal',
                                               disabled=not controls_enabled)
            self.vent_button = gui.add_button('Vent', color='red',
                                              disabled=not controls_enabled)
            self.tip_button = gui.add_button('Send tip target', disabled=not controls_enabled)
            self.control_status = gui.add_markdown('')
        with gui.add_folder('Camera'):
            self.camera = gui.add_image(np.full((120, 160, 3), 40, np.uint8), label='camera',
                                        format='jpeg', jpeg_quality=80)
        with gui.add_folder(f'Plots (last {history_s:g} s)'):
            self.plots: dict[str, tuple[ScrollingPlot, object]] = {}
            colours = ('#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd')
            for key, title, labels in (
                    ('tracking', 'soft arm: end to planned path [mm]', ('true end', 'camera')),
                    ('pressures', 'chamber pressures [kPa]', CHAMBERS),
                    ('load', 'estimated tip load [N]', ('|F|',)),
                    ('margins', 'wrinkling margin [N m]', ('link_1', 'link_2'))):
                plot = ScrollingPlot(labels, history_s)
                series = (uplot.Series(label='t [s]'),) + tuple(
                    uplot.Series(label=label, stroke=colour, width=2)
                    for label, colour in zip(labels, colours, strict=False))
                handle = gui.add_uplot(
                    data=plot.arrays(0.0), series=series, title=title, aspect=2.2,
                    scales={'x': uplot.Scale(time=False, auto=False, range=(-history_s, 0.0))},
                    legend=uplot.Legend(show=True))
                self.plots[key] = (plot, handle)

        self.goal = scene.add_transform_controls(
            f'/{SRA_FRAME}/goal', scale=0.12, disable_rotations=True, position=tuple(goal),
            visible=True)
        scene.add_icosphere(f'/{SRA_FRAME}/goal/marker', radius=0.012, color=PATH_COLOUR,
                            opacity=0.6)
        self.tip_goal = scene.add_transform_controls(
            f'/{BASE_LINK}/tip_target', scale=0.15, disable_rotations=True,
            position=tuple(tip_target))
        scene.add_icosphere(f'/{BASE_LINK}/tip_target/marker', radius=0.015,
                            color=TRAJECTORY_COLOUR, opacity=0.6)
        if controls_enabled:
            def on_dropped(action: Callable[[], str]) -> Callable:
                def callback(event) -> None:
                    if event.phase == 'end':  # once, where the gizmo was let go
                        self._report(action())
                return callback
            self.goal.on_update(on_dropped(lambda: self.controls.plan_to(self.goal_point())))
            self.tip_goal.on_update(
                on_dropped(lambda: self.controls.tip_target(self.tip_target_point())))
            self.goal_button.on_click(
                lambda _: self._report(self.controls.plan_to(self.goal_point())))
            self.trial_button.on_click(
                lambda _: self._report(self.controls.start_trial(self.goal_point())))
            self.vent_button.on_click(lambda _: self._report(self.controls.vent()))
            self.tip_button.on_click(
                lambda _: self._report(self.controls.tip_target(self.tip_target_point())))

    # --- controls -----------------------------------------------------------------------------

    def goal_point(self) -> npt.NDArray[np.float64]:
        """The soft arm's goal where its gizmo is, in ``sra_mount`` [m]."""
        return np.asarray(self.goal.position, dtype=float)

    def tip_target_point(self) -> npt.NDArray[np.float64]:
        """The inflatable arm's tip target where its gizmo is, in ``base_link`` [m]."""
        return np.asarray(self.tip_goal.position, dtype=float)

    def _report(self, text: str) -> None:
        self.control_status.content = text

    # --- drawing ------------------------------------------------------------------------------

    def _changed(self, key: str, value) -> bool:
        """Whether ``value`` differs from what ``key`` shows (and remember it)."""
        old = self._last.get(key, _MISSING)
        if old is not _MISSING and _same(old, value):
            return False
        self._last[key] = value
        return True

    def set_status(self, lines: Sequence[str]) -> None:
        text = '**inflarm live view**  \n' + '  \n'.join(lines)
        if self._changed('status', text):
            self.status.content = text

    def set_robot(self, robot: RobotModel) -> None:
        """Draw the arm of this URDF from now on (its cylinders rebuilt)."""
        scene = self.server.scene
        for key in [k for k in self._last if k.startswith('arm/')]:
            del self._last[key]
        self._robot = robot
        self._arm_handles: dict[str, object] = {}
        self._ghost_handles: dict[str, object] = {}
        visuals, _ = robot.poses({})
        for v in visuals:
            self._arm_handles[v.name] = scene.add_cylinder(
                f'/{BASE_LINK}/arm/{v.name}', radius=v.radius, height=v.length,
                color=FABRIC_COLOUR, visible=False)
            self._ghost_handles[v.name] = scene.add_cylinder(
                f'/{BASE_LINK}/rigid/{v.name}', radius=v.radius * 1.02, height=v.length,
                color=GHOST_COLOUR, opacity=0.25, visible=False)

    def draw_inflatable_arm(self, positions: Mapping[str, float] | None,
                            margins: Mapping[str, tuple[float, float]],
                            tip_truth: npt.ArrayLike | None,
                            tip_estimate: npt.ArrayLike | None,
                            trajectory: npt.ArrayLike | None) -> None:
        """The deflected arm at ``positions`` (every joint, springs included) with each
        inflated link coloured by ``margins`` (link -> (margin, wrinkling moment) [N m]), the
        rigid arm at the same motor angles, the true and estimated tips and the commanded tip
        trajectory (N, 3), all in ``base_link`` [m]."""
        if self._robot is not None and positions is not None:
            for handles, pose_of, key in ((self._arm_handles, positions, 'arm/pose'),
                                          (self._ghost_handles, rigid_positions(positions),
                                           'arm/rigid')):
                if not self._changed(key, dict(pose_of)):
                    continue
                for v in self._robot.poses(pose_of)[0]:
                    handle = handles[v.name]
                    handle.position = tuple(v.pose[:3, 3])
                    handle.wxyz = tuple(_wxyz(v.pose))
                    handle.visible = True
            for name, link in self._robot.visual_links.items():
                colour = margin_colour(*margins[link]) if link in margins else FABRIC_COLOUR
                if self._changed(f'arm/colour/{name}', colour):
                    self._arm_handles[name].color = colour
        self._point(f'/{BASE_LINK}/tip_truth', tip_truth, TRUTH_COLOUR, 0.02)
        self._point(f'/{BASE_LINK}/tip_estimate', tip_estimate, ESTIMATE_COLOUR, 0.016)
        self._polyline(f'/{BASE_LINK}/tip_trajectory', trajectory, TRAJECTORY_COLOUR, 0.004)

    def draw_load(self, positions: Mapping[str, float], force_tip_frame: npt.ArrayLike) -> None:
        """The estimated tip force (``force_tip_frame`` [N], in the ``tip`` frame of the arm at
        ``positions``) as an arrow at that tip, turned into ``base_link``, 1 cm per newton."""
        if self._robot is None:
            return
        tip = self._robot.poses(positions)[1]
        force = tip[:3, :3] @ np.asarray(force_tip_frame, dtype=float)
        arrow = np.stack([tip[:3, 3], tip[:3, 3] + FORCE_SCALE_M_PER_N * force])[None]
        if self._changed('arm/load', arrow):
            self.server.scene.add_arrows(f'/{BASE_LINK}/load', points=arrow,
                                         colors=ESTIMATE_COLOUR, shaft_radius=0.006,
                                         head_radius=0.016, head_length=0.04)

    def draw_soft_arm(self, ball: npt.ArrayLike | None, end_truth: npt.ArrayLike | None,
                      path: npt.ArrayLike | None, obstacles: ObstacleSet | None) -> None:
        """The actuators' central axes at the measured end (``ball``), the ball, the true end,
        the planned path (N, 3) and the obstacles with their alert regions, in ``sra_mount``."""
        scene = self.server.scene
        self._point(f'/{SRA_FRAME}/ball', ball, BALL_COLOUR, 0.02)
        self._point(f'/{SRA_FRAME}/end_truth', end_truth, TRUTH_COLOUR, 0.008)
        if ball is not None and float(np.asarray(ball)[2]) > 0.0:
            axes = central_axes(np.asarray(ball, dtype=float))
            if self._changed('sra/axes', axes):
                scene.add_line_segments(f'/{SRA_FRAME}/axes', points=axes, colors=AXIS_COLOUR,
                                        thickness=0.05)
        self._polyline(f'/{SRA_FRAME}/planned_path', path, PATH_COLOUR, 0.008)
        if obstacles is not None and self._changed('sra/obstacles', obstacles):
            for key in [k for k in self._last if k.startswith('sra/box/')]:
                scene.remove_by_name(key[len('sra/box'):])
                del self._last[key]
            for name, centre, size, alert in obstacle_boxes(obstacles):
                scene.add_box(f'/{SRA_FRAME}/{name}', dimensions=tuple(size),
                              position=tuple(centre),
                              color=ALERT_COLOUR if alert else OBSTACLE_COLOUR,
                              opacity=0.15 if alert else 0.5, cast_shadow=False,
                              receive_shadow=False)
                self._last[f'sra/box/{SRA_FRAME}/{name}'] = True

    def _point(self, name: str, point, colour, radius: float) -> None:
        if point is None:
            return
        point = tuple(float(v) for v in point)
        if name not in self._last:
            self._last[name + '/handle'] = self.server.scene.add_icosphere(
                name, radius=radius, color=colour, position=point)
            self._last[name] = point
        elif self._changed(name, point):
            self._last[name + '/handle'].position = point

    def _polyline(self, name: str, points, colour, thickness: float) -> None:
        if points is None:
            return
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) < 2 or not self._changed(name, points):
            return
        segments = np.stack([points[:-1], points[1:]], axis=1)
        self.server.scene.add_line_segments(name, points=segments, colors=colour,
                                            thickness=thickness)

    def set_camera_image(self, rgb: npt.NDArray[np.uint8]) -> None:
        """Show an RGB image (H, W, 3) in the camera panel."""
        self.camera.image = rgb

    def sample_plots(self, now: float, values: Mapping[str, Sequence[float]]) -> None:
        """Add one sample to each plot named in ``values`` (NaN: none for that series)."""
        for key, sample in values.items():
            self.plots[key][0].add(now, sample)

    def draw_plots(self, now: float) -> None:
        """Resend the plots that have samples, scrolled to ``now`` [s]."""
        for plot, handle in self.plots.values():
            if len(plot):
                handle.data = plot.arrays(now)


_MISSING = object()


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.array_equal(a, b))
    return a == b
