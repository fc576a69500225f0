"""A* path planning of the soft arm's end around cuboid obstacles (section 4 of 001_...).

A plan request (topic or service) is planned with ``inflarm_planning.trajectory.plan_trajectory``
against the latest obstacles: A* on the work-space grid, then shortcut, smoothed, resampled to
``trajectory.max_step_m`` and timed. The path is published latched for the pressure controller
(which follows it with a reference moving along it: `inflarm_control.path_following`), with
markers of the scene. When the obstacles change,
the last request's goal is planned again, from the measured end point if one is fresh (else from
the request's start). A plan that finds no path publishes none; its PlanOutcome gives the
NoPathError's reason and text. Invalid input (``ValueError`` from ``inflarm_planning.requests``
and the message decoder) is rejected by the node's guards with a warning, and nothing is
published; the service also answers it with a Path without poses and a ``rejected`` outcome.

Threads: requests from the ``plan_request`` topic and replans are planned on one daemon worker
thread (`inflarm_msgs_json.ros.worker.LatestJobWorker`: the latest pending request wins; numba's
A* kernel runs without the GIL), so the executor keeps spinning whatever the resolution; the
results are published from the executor thread; a stop waits at most ``STOP_WAIT_S`` for a plan
under way. The ``~/plan`` service plans inside its
callback, which blocks the executor for the plan's duration, so it refuses grids larger than
``service.max_cells`` (default: 2 mm and coarser).

Subscribes:
    obstacles (std_msgs/String: ObstacleSet JSON, LATCHED_QOS): the boxes and alert margin,
        frame ``frame_id``.
    plan_request (std_msgs/String: PlanRequest JSON, RELIABLE_QOS): start, goal, resolution.
    ball_position (geometry_msgs/PointStamped, SENSOR_QOS): measured end point, the start of
        replans.
Publishes:
    planned_path (nav_msgs/Path, LATCHED_QOS): waypoints [m] in ``frame_id``, each pose stamped
        with the time it is due.
    planning_markers (visualization_msgs/MarkerArray, LATCHED_QOS): obstacles, alert regions and
        the path.
    ~/plan_outcome (std_msgs/String: PlanOutcome JSON, LATCHED_QOS): the outcome of every
        plan (the path's figures, or why there is none) and of every rejected service request.
Services:
    ~/plan (nav_msgs/GetPlan): plan from ``start`` to ``goal`` (poses in ``frame_id``) at
        ``service.resolution_m``; the answer is the path, or a Path without poses when there is
        none (the reason is on ``~/plan_outcome``, published before the answer, and in the log).
        ``tolerance`` is not used.
Parameters:
    frame_id (read-only), min_alert_margin_m, cost, connectivity, service.resolution_m,
    service.max_cells, trajectory.max_step_m, trajectory.max_speed_mps, trajectory.max_accel_mps2,
    trajectory.smoothing, trajectory.check_step_m, replan.position_timeout_s,
    max_cells (read-only).
"""

from dataclasses import dataclass
import math
import time

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rclpy.node import Node
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from inflarm_msgs_json import ObstacleSet, PlanOutcome, PlanRequest
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node
from inflarm_msgs_json.ros.worker import LatestJobWorker
from inflarm_planning.astar import NoPathError
from inflarm_planning.collision import CHECK_STEP
from inflarm_planning.free_space import MAX_CELLS
from inflarm_planning.grid_search import CONNECTIVITIES, check_connectivity
from inflarm_planning.requests import (
    ObstacleModel,
    PlanQuery,
    check_cost,
    check_frame,
    obstacle_model,
    plan_query,
)
from inflarm_planning.ros_conversions import (
    empty_path,
    point_of,
    scene_markers,
    trajectory_to_path,
)
from inflarm_planning.scenario import ALERT_MARGIN
from inflarm_planning.trajectory import TrajectoryPlan, plan_trajectory

PARAMETERS = (
    Parameter('frame_id', 'sra_mount', 'frame of obstacles, requests and paths',
              read_only=True),
    Parameter('min_alert_margin_m', ALERT_MARGIN,
              'smallest alert margin planned with [m]: more than half the actuator width (50 mm '
              'assumed) plus the 5 mm tracking error; larger ObstacleSet margins are kept',
              range=(0.0, 0.2)),
    Parameter('cost', 'length', "A* cost: 'length' (path length + Euclidean) or 'paper' "
              '(eq. 7: Manhattan length + Euclidean)'),
    Parameter('connectivity', 26,
              f'A* neighbours of a grid point, one of {CONNECTIVITIES}: faces (6), faces and '
              "edges (18), the 3x3x3 cube (26: the 3-D form of the paper's 8 neighbours, "
              'the shortest paths); checked at runtime', range=(6, 26)),
    Parameter('service.resolution_m', 0.005, 'grid spacing of ~/plan requests [m]',
              range=(0.0005, 0.1)),
    Parameter('service.max_cells', 10_000_000,
              'largest grid ~/plan plans in its callback (it blocks the node meanwhile)',
              range=(1, MAX_CELLS)),
    Parameter('trajectory.max_step_m', 0.005, 'largest waypoint spacing [m]',
              range=(0.0005, 0.1)),
    Parameter('trajectory.max_speed_mps', 0.005, 'cruise speed of the timing [m/s]',
              range=(1e-4, 1.0)),
    Parameter('trajectory.max_accel_mps2', 0.005, 'acceleration of the timing [m/s^2]',
              range=(1e-4, 10.0)),
    Parameter('trajectory.smoothing', 3, 'Chaikin corner-cutting iterations', range=(0, 8)),
    Parameter('trajectory.check_step_m', CHECK_STEP,
              'pose spacing of the continuous collision tests [m]', range=(1e-4, 0.01)),
    Parameter('replan.position_timeout_s', 1.0,
              'a ball_position older than this is not used as the start of a replan [s]',
              range=(0.0, 60.0)),
    Parameter('max_cells', MAX_CELLS, 'largest planning grid (memory: ~11 bytes a point)',
              range=(1, 500_000_000), read_only=True),
)


STOP_WAIT_S = 0.5
"""How long ``destroy_node`` waits for a plan under way before leaving it to finish alone."""


@dataclass(frozen=True)
class Job:
    """One plan to make: a request against an obstacle model."""

    query: PlanQuery
    model: ObstacleModel
    source: str  # 'plan_request', 'replan' or 'service', for the log
    settings: dict  # the parameters when the job was made


@dataclass(frozen=True)
class Result:
    """What a job gave: a plan, or the error that stopped it."""

    job: Job
    planned: TrajectoryPlan | None
    outcome: PlanOutcome


def check_planner_parameters(p: dict) -> None:
    """Raise ValueError naming a bad ``cost`` or ``connectivity``."""
    check_cost(p['cost'])
    check_connectivity(p['connectivity'])


class PathPlanner(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('path_planner', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, check=check_planner_parameters)
        check_planner_parameters(self.params)
        self.frame_id = self.params['frame_id']
        self.model = ObstacleModel((), self.params['min_alert_margin_m'], 0.0)
        self.last_query: PlanQuery | None = None  # what a replan repeats
        self.last_path = None  # points of the last published path, for the markers
        self.position: tuple[float, float, float] | None = None
        self.position_time_ns = 0
        self.last_request: PlanQuery | None = None  # accepted from the topic

        self._done = self.create_guard_condition(self.problems.guard('results', self.on_results))
        self.worker = LatestJobWorker('path_planner worker', self.run, self._done.trigger)

        self.path_pub = self.create_publisher(
            Path, 'planned_path', LATCHED_QOS, event_callbacks=publisher_events(
                self, 'planned_path'))
        self.marker_pub = self.create_publisher(
            MarkerArray, 'planning_markers', LATCHED_QOS, event_callbacks=publisher_events(
                self, 'planning_markers'))
        self.outcome_pub = self.create_publisher(
            String, '~/plan_outcome', LATCHED_QOS, event_callbacks=publisher_events(
                self, '~/plan_outcome'))
        self.create_guarded_subscription(String, 'obstacles', self.on_obstacles, LATCHED_QOS)
        self.create_guarded_subscription(String, 'plan_request', self.on_plan_request,
                                         RELIABLE_QOS)
        self.create_guarded_subscription(PointStamped, 'ball_position', self.on_ball_position,
                                         SENSOR_QOS)
        self.create_guarded_service(GetPlan, '~/plan', self.on_plan_service)
        self.get_logger().info(
            f"ready: frame '{self.frame_id}', alert margin >= "
            f"{self.params['min_alert_margin_m']:.3f} m, cost '{self.params['cost']}', "
            f"{self.params['connectivity']}-connected, service "
            f"grids up to {self.params['service.max_cells']:.3g} points")

    # -- inputs ----------------------------------------------------------------------------------

    def on_obstacles(self, msg: String) -> None:
        model = obstacle_model(from_string_msg(msg, expected=ObstacleSet), self.frame_id,
                               self.params['min_alert_margin_m'])  # else the old ones stay
        if model.raised:
            self.get_logger().warning(
                f'obstacles: alert margin {model.requested_margin:.3f} m raised to '
                f'{model.alert_margin:.3f} m (min_alert_margin_m: half the actuator width + '
                f'tracking error)', throttle_duration_sec=2.0)
        self.model = model
        self.get_logger().info(
            f'{len(model.obstacles)} obstacles, alert margin {model.alert_margin:.3f} m',
            throttle_duration_sec=1.0)
        self.publish_markers()
        if self.last_query is not None:
            self.submit(self.job(self.replan_query(self.last_query), 'replan'))

    def on_ball_position(self, msg: PointStamped) -> None:
        check_frame(msg.header.frame_id, self.frame_id, 'ball_position')
        point = (msg.point.x, msg.point.y, msg.point.z)
        if not all(math.isfinite(v) for v in point):
            raise InputError('non-finite', f'ball_position: expected finite coordinates [m], '
                                           f'got {list(point)}')
        self.position = point
        self.position_time_ns = self.get_clock().now().nanoseconds

    def replan_query(self, query: PlanQuery) -> PlanQuery:
        """The last request's goal, from the measured end point when it is fresh."""
        age_s = (self.get_clock().now().nanoseconds - self.position_time_ns) * 1e-9
        if self.position is None or age_s > self.params['replan.position_timeout_s'] \
                or self.position == query.goal:
            return query
        return PlanQuery(self.position, query.goal, query.resolution)

    def on_plan_request(self, msg: String) -> None:
        request = from_string_msg(msg, expected=PlanRequest)
        query = plan_query(request.start, request.goal, request.resolution,
                           (request.frame_id,), self.frame_id, self.params['max_cells'])
        self.last_request = query
        self.submit(self.job(query, 'plan_request'))

    def on_plan_service(self, request: GetPlan.Request, response: GetPlan.Response):
        response.plan = empty_path(self.frame_id, self.get_clock().now().to_msg())
        start, goal = point_of(request.start), point_of(request.goal)
        try:
            query = plan_query(
                start, goal, self.params['service.resolution_m'],
                (request.start.header.frame_id, request.goal.header.frame_id), self.frame_id,
                min(self.params['service.max_cells'], self.params['max_cells']),
                limit='for the plan service (it plans in its callback, blocking the node: '
                      'publish a PlanRequest on plan_request, planned in the background)')
        except ValueError as err:
            # GetPlan has no status field: the reason goes on ~/plan_outcome, then the guard
            # logs the rejection and the answer is the Path without poses
            self.outcome_pub.publish(to_string_msg(PlanOutcome(
                status='rejected', reason='', message=f'~/plan rejected: {err}',
                start=_finite(start), goal=_finite(goal), waypoints=0, length=0.0,
                duration=0.0, planning_time=0.0)))
            raise
        path = self.publish_result(self.run(self.job(query, 'service')))
        if path is not None:
            response.plan = path
        return response

    def job(self, query: PlanQuery, source: str) -> Job:
        """A job for ``query`` against the current obstacles; it is what a replan repeats."""
        self.last_query = query
        return Job(query, self.model, source, dict(self.params))

    # -- planning --------------------------------------------------------------------------------

    def submit(self, job: Job) -> None:
        """Plan ``job`` on the worker thread; a newer job replaces one still waiting (a stop
        during a long plan, a 1 mm grid build takes seconds, is not held up by it)."""
        if self.worker.submit(job):
            self.get_logger().info('a newer request replaces the one waiting')

    def run(self, job: Job) -> Result:
        """Plan one job (any thread): never raises, the error goes into the outcome."""
        p = job.settings
        q = job.query
        started = time.perf_counter()
        planned, status, reason = None, 'planned', ''
        try:
            planned = plan_trajectory(
                q.start, q.goal, job.model.obstacles, q.resolution, job.model.alert_margin,
                cost=p['cost'], connectivity=p['connectivity'],
                max_step=p['trajectory.max_step_m'],
                max_speed=p['trajectory.max_speed_mps'], max_accel=p['trajectory.max_accel_mps2'],
                smoothing=p['trajectory.smoothing'], check_step=p['trajectory.check_step_m'],
                max_cells=p['max_cells'])
        except NoPathError as err:
            status, reason, message = 'no_path', err.reason, f'no path: {err}'
        except ValueError as err:
            status, message = 'rejected', f'plan request rejected: {err}'
        except Exception as err:  # noqa: BLE001 (a bug must not stop the worker for good)
            self.problems.bug(job.source, err)
            status, message = 'rejected', f'internal error: {type(err).__name__}: {err}'
        elapsed = time.perf_counter() - started
        if planned is None:
            return Result(job, None, PlanOutcome(
                status=status, reason=reason, message=message, start=q.start, goal=q.goal,
                waypoints=0, length=0.0, duration=0.0, planning_time=elapsed))
        t = planned.trajectory
        grid = planned.grid
        message = (f'{len(t.points)} waypoints, {t.length * 1e3:.1f} mm, {t.duration:.1f} s '
                   f'(grid path {grid.length * 1e3:.1f} mm at {q.resolution * 1e3:g} mm, '
                   f'{grid.expanded} cells expanded; {elapsed * 1e3:.0f} ms, of which '
                   f'free-space build {grid.free_space.build_time_s * 1e3:.0f} ms if new)')
        return Result(job, planned, PlanOutcome(
            status='planned', reason='', message=message, start=q.start, goal=q.goal,
            waypoints=len(t.points), length=t.length, duration=t.duration,
            planning_time=elapsed))

    def on_results(self) -> None:
        for result in self.worker.results():
            if isinstance(result, Exception):
                raise result  # run() catches what planning raises: a bug, reported by the guard
            self.publish_result(result)

    def publish_result(self, result: Result) -> Path | None:
        """Publish a result (executor thread); return the path published, if any."""
        job, outcome = result.job, result.outcome
        if job.model is not self.model:  # the obstacles changed meanwhile: a replan follows
            self.get_logger().info(f'{job.source}: dropped, planned for obstacles since replaced')
            return None
        self.outcome_pub.publish(to_string_msg(outcome))
        if result.planned is None:
            note = (' (the previous path no longer fits the obstacles)'
                    if job.source == 'replan' else '')
            self.get_logger().warning(f'{job.source}: {outcome.message}{note}')
            return None
        path = trajectory_to_path(result.planned.trajectory, self.frame_id,
                                  self.get_clock().now())
        self.path_pub.publish(path)
        self.last_path = result.planned.trajectory.points
        self.publish_markers(job.model)
        self.get_logger().info(f'{job.source}: planned {outcome.message}')
        return path

    def publish_markers(self, model: ObstacleModel | None = None) -> None:
        model = self.model if model is None else model
        self.marker_pub.publish(scene_markers(
            model.obstacles, model.alert_margin, self.last_path, self.frame_id,
            self.get_clock().now().to_msg()))

    def destroy_node(self) -> None:
        self.worker.close(STOP_WAIT_S)  # a short plan under way may still finish
        super().destroy_node()


def _finite(point) -> tuple[float, float, float]:
    """A point for a PlanOutcome: NaN or infinite coordinates (a rejected request's) as 0."""
    return tuple(float(v) if abs(float(v)) < float('inf') else 0.0 for v in point)


def main(args: list[str] | None = None) -> None:
    spin_node(PathPlanner, args)


if __name__ == '__main__':
    main()
