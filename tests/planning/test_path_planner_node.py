"""path_planner in-process: requests by topic and service, failures, bad input, replanning."""

import json

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from inflarm_msgs_json import ObstacleSet, PlanOutcome, PlanRequest, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
from inflarm_planning.astar import Cuboid
from inflarm_planning.nodes.path_planner import PathPlanner
from inflarm_planning.requests import PlanQuery
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
from planning_reference import violations
from ros_harness import spin_until

FRAME = 'sra_mount'
# keep every latched message the planner sends, not only the last
KEEP_ALL = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def points_of(path: Path) -> np.ndarray:
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in path.poses])


class Rig:
    """The planner plus a probe node publishing obstacles and requests and recording outputs."""

    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.planner = PathPlanner(
            context=executor.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.paths: list[Path] = []
        self.markers: list[MarkerArray] = []
        self.outcomes: list[PlanOutcome] = []
        self.probe.create_subscription(Path, 'planned_path', self.paths.append, KEEP_ALL)
        self.probe.create_subscription(MarkerArray, 'planning_markers', self.markers.append,
                                       KEEP_ALL)
        self.probe.create_subscription(String, '/path_planner/plan_outcome',
                                       lambda m: self.outcomes.append(decode(m.data)), KEEP_ALL)
        self.obstacle_pub = self.probe.create_publisher(String, 'obstacles', LATCHED_QOS)
        self.request_pub = self.probe.create_publisher(String, 'plan_request', RELIABLE_QOS)
        self.ball_pub = self.probe.create_publisher(PointStamped, 'ball_position', SENSOR_QOS)
        self.client = self.probe.create_client(GetPlan, '/path_planner/plan')
        executor.add_node(self.planner)
        executor.add_node(self.probe)
        assert spin_until(executor, lambda: (
            self.request_pub.get_subscription_count() == 1
            and self.obstacle_pub.get_subscription_count() == 1
            and self.planner.outcome_pub.get_subscription_count() == 1
            and self.planner.path_pub.get_subscription_count() == 1))

    def obstacles(self, boxes=(OBSTACLE,), margin=0.01, frame_id=FRAME) -> None:
        self.obstacle_pub.publish(to_string_msg(ObstacleSet(
            frame_id=frame_id, alert_margin=margin,
            obstacles=tuple(b.to_message() for b in boxes))))

    def request(self, start=START, goal=GOAL, resolution=0.01, frame_id=FRAME) -> None:
        self.request_pub.publish(to_string_msg(PlanRequest(frame_id, start, goal, resolution)))

    def wait_outcomes(self, count: int, timeout_s: float = 20.0) -> PlanOutcome:
        assert spin_until(self.executor, lambda: len(self.outcomes) >= count, timeout_s), (
            f'{len(self.outcomes)} outcomes')
        return self.outcomes[count - 1]

    def call(self, start, goal, frame_id=FRAME) -> GetPlan.Response:
        assert self.client.wait_for_service(timeout_sec=5.0)
        request = GetPlan.Request()
        for pose, point in ((request.start, start), (request.goal, goal)):
            pose.header.frame_id = frame_id
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = point
        future = self.client.call_async(request)
        self.executor.spin_until_future_complete(future, timeout_sec=20.0)
        assert future.done()
        return future.result()

    def spin(self, seconds: float) -> None:
        spin_until(self.executor, lambda: False, timeout_s=seconds)


def test_defaults_and_parameter_checks(executor):
    rig = Rig(executor)
    node = rig.planner
    assert node.get_parameter('min_alert_margin_m').value == ALERT_MARGIN
    assert node.get_parameter('cost').value == 'length'
    assert node.get_parameter('frame_id').value == FRAME
    assert not node.set_parameters([Parameter('cost', value='manhattan')])[0].successful
    assert node.set_parameters([Parameter('cost', value='paper')])[0].successful
    assert node.params['cost'] == 'paper'
    assert not node.set_parameters([Parameter('frame_id', value='world')])[0].successful
    assert not node.set_parameters([Parameter('service.resolution_m', value=0.0)])[0].successful
    assert node.get_parameter('connectivity').value == 26
    refused = node.set_parameters([Parameter('connectivity', value=8)])[0]
    assert not refused.successful
    assert 'expected connectivity in (6, 18, 26)' in refused.reason, refused.reason
    assert not node.set_parameters([Parameter('connectivity', value=27)])[0].successful
    assert node.params['connectivity'] == 26


def test_a_connectivity_out_of_the_three_is_refused_at_start(executor):
    with pytest.raises(ValueError, match=r'connectivity in \(6, 18, 26\), got 8'):
        PathPlanner(context=executor.context,
                    parameter_overrides=[Parameter('connectivity', value=8)])


def test_the_connectivity_set_at_runtime_is_planned_with(executor):
    rig = Rig(executor)
    assert rig.planner.set_parameters([Parameter('connectivity', value=6)])[0].successful
    rig.obstacles()
    assert spin_until(executor, lambda: len(rig.planner.model.obstacles) == 1)
    rig.request(resolution=0.005)
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'planned', outcome.message
    assert 'grid path 280.0 mm at 5 mm' in outcome.message  # 6-connected (26: 258.1 mm)


def test_a_plan_request_publishes_the_path_markers_and_outcome(executor):
    rig = Rig(executor)
    rig.obstacles(margin=0.01)  # below the node's minimum: planned with 30 mm
    assert spin_until(executor, lambda: len(rig.planner.model.obstacles) == 1)
    assert rig.planner.model.alert_margin == ALERT_MARGIN
    rig.request()
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'planned', outcome.message
    assert spin_until(executor, lambda: len(rig.paths) == 1)
    path = rig.paths[0]
    assert path.header.frame_id == FRAME and all(p.header.frame_id == FRAME for p in path.poses)
    points = points_of(path)
    np.testing.assert_allclose(points[[0, -1]], [START, GOAL], atol=1e-12)
    assert violations(points, [OBSTACLE.bounds], ALERT_MARGIN) == []
    assert np.linalg.norm(np.diff(points, axis=0), axis=1).max() <= 0.005 + 1e-9
    stamps = [p.header.stamp.sec + p.header.stamp.nanosec * 1e-9 for p in path.poses]
    assert np.all(np.diff(stamps) > 0)
    assert stamps[-1] - stamps[0] == pytest.approx(outcome.duration, abs=1e-6)
    assert outcome.waypoints == len(path.poses)
    assert outcome.length == pytest.approx(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    assert outcome.start == START and outcome.goal == GOAL and outcome.planning_time > 0
    assert spin_until(executor, lambda: any(
        any(m.ns == 'path' for m in array.markers) for array in rig.markers))
    markers = [a for a in rig.markers if any(m.ns == 'path' for m in a.markers)][-1].markers
    assert markers[0].action == Marker.DELETEALL
    by_ns = {m.ns: m for m in markers[1:]}
    assert set(by_ns) == {'obstacles', 'alert_regions', 'path'}
    extent = np.subtract(OBSTACLE.max_corner, OBSTACLE.min_corner)
    alert = by_ns['alert_regions'].scale
    np.testing.assert_allclose([alert.x, alert.y, alert.z], extent + 2 * ALERT_MARGIN)
    assert len(by_ns['path'].points) == len(path.poses)
    assert all(m.header.frame_id == FRAME for m in markers)


def test_a_failed_plan_publishes_no_path_and_says_why(executor):
    rig = Rig(executor)
    rig.obstacles()
    assert spin_until(executor, lambda: len(rig.planner.model.obstacles) == 1)
    rig.request(start=(0.1, 0.1, 0.7))  # inside the obstacle
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'no_path' and outcome.reason == 'start_blocked'
    assert "is not free: the end is inside obstacle 0 'paper obstacle'" in outcome.message
    assert outcome.waypoints == 0
    rig.request(goal=(0.3, 0.0, 0.7))
    outcome = rig.wait_outcomes(2)
    assert outcome.reason == 'outside_workspace' and 'goal x = 0.300 m' in outcome.message
    rig.spin(0.3)
    assert rig.paths == []


def test_bad_input_is_rejected_and_the_node_keeps_running(executor):
    rig = Rig(executor)
    node = rig.planner
    rig.obstacles()
    assert spin_until(executor, lambda: len(node.model.obstacles) == 1)
    model = node.model
    degenerate = json.loads(to_string_msg(ObstacleSet(FRAME, 0.01,
                                                      (OBSTACLE.to_message(),))).data)
    degenerate['obstacles'][0]['min'][0] = 0.5  # min > max
    far = ObstacleSet(FRAME, 0.01, (Cuboid((0, 0, 0.7), (1e4, 0.1, 0.8)).to_message(),))
    bad_obstacles = [
        (json.dumps(degenerate), 'expected min <= max'),
        (to_string_msg(ObstacleSet(FRAME, 0.01, ())).data.replace('0.01', 'NaN'), 'NaN'),
        (to_string_msg(ObstacleSet('world', 0.01, ())).data, "frame_id 'world'"),
        (to_string_msg(ObstacleSet(FRAME, 5.0, ())).data, 'alert_margin 5 m is above'),
        (to_string_msg(far).data, 'more than 1000 m from the mount'),
    ]
    # straight into the subscription's (guarded) callback: a latched topic of depth 1 would
    # keep only the last of several quick messages
    callback = next(s for s in node.subscriptions if s.topic_name == '/obstacles').callback
    for n, (text, expected) in enumerate(bad_obstacles, start=1):
        callback(String(data=text))
        assert node.problems.counts['obstacles'] == n
        assert expected in node.problems.last['obstacles'], node.problems.last['obstacles']
        assert node.model is model  # refused: the obstacles are unchanged

    bad_requests = [
        ('{"type":"PlanRequest","schema_version":1,"frame_id":"sra_mount",'
         '"start":[0,0.13,NaN],"goal":[0.13,0,0.73],"resolution":0.01}', 'NaN'),
        (to_string_msg(PlanRequest('world', START, GOAL, 0.01)).data,
         "frame_id 'world' is not 'sra_mount'"),
        (to_string_msg(PlanRequest(FRAME, START, START, 0.01)).data,
         'start and goal are the same point'),
        (to_string_msg(PlanRequest(FRAME, START, GOAL, 0.0005)).data,
         'too fine for memory: 5.45e+08 grid points'),
        (to_string_msg(PlanRequest(FRAME, START, GOAL, 1e-300)).data, 'too fine for memory'),
        ('{"type":"PlanRequest","schema_version":1,"frame_id":"sra_mount",'
         '"start":[0,0.13,0.71],"goal":[0.13,0,0.73],"resolution":0}', 'PlanRequest.resolution'),
    ]
    for n, (text, expected) in enumerate(bad_requests, start=1):
        rig.request_pub.publish(String(data=text))
        assert spin_until(executor, lambda n=n: node.problems.counts.get('plan_request') == n)
        assert expected in node.problems.last['plan_request'], node.problems.last['plan_request']
    assert node.problems.unexpected == 0
    rig.spin(0.2)
    assert rig.outcomes == [] and rig.paths == []
    rig.request()
    assert rig.wait_outcomes(1).status == 'planned'
    assert spin_until(executor, lambda: len(rig.paths) == 1)


def test_the_service_answers_with_the_path_or_with_none(executor):
    rig = Rig(executor, **{'service.resolution_m': 0.01})
    rig.obstacles()
    assert spin_until(executor, lambda: len(rig.planner.model.obstacles) == 1)
    response = rig.call(START, GOAL)
    points = points_of(response.plan)
    assert response.plan.header.frame_id == FRAME and len(points) > 10
    np.testing.assert_allclose(points[[0, -1]], [START, GOAL], atol=1e-12)
    assert violations(points, [OBSTACLE.bounds], ALERT_MARGIN) == []
    assert spin_until(executor, lambda: len(rig.paths) == 1)  # published for the controller too
    np.testing.assert_allclose(points_of(rig.paths[0]), points)
    assert rig.wait_outcomes(1).status == 'planned'

    failed = rig.call(START, (0.2, 0.2, 0.72))
    assert failed.plan.poses == [] and failed.plan.header.frame_id == FRAME
    outcome = rig.wait_outcomes(2)  # published before the answer
    assert outcome.reason == 'goal_blocked' and 'PEA2 axis crosses' in outcome.message
    wrong_frame = rig.call(START, GOAL, frame_id='world')
    assert wrong_frame.plan.poses == []
    assert "frame_id 'world'" in rig.wait_outcomes(3).message
    rig.spin(0.2)
    assert len(rig.paths) == 1


def test_the_service_refuses_grids_that_would_block_the_node(executor):
    rig = Rig(executor, **{'service.resolution_m': 0.001})
    response = rig.call(START, GOAL)
    assert response.plan.poses == []
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'rejected'
    assert 'too fine for the plan service' in outcome.message
    assert 'publish a PlanRequest on plan_request' in outcome.message


def test_changed_obstacles_are_planned_around_from_the_measured_end(executor):
    rig = Rig(executor)
    rig.request()  # no obstacles yet: straight through where the box will be
    assert rig.wait_outcomes(1).status == 'planned'
    assert spin_until(executor, lambda: len(rig.paths) == 1)
    assert violations(points_of(rig.paths[0]), [OBSTACLE.bounds], 0.0) != []
    here = (0.0, 0.12, 0.71)
    ball = PointStamped()
    ball.header.frame_id = FRAME
    ball.point.x, ball.point.y, ball.point.z = here
    assert spin_until(executor, lambda: (rig.ball_pub.publish(ball), rig.planner.position)[1]
                      is not None)
    rig.obstacles()
    outcome = rig.wait_outcomes(2)
    assert outcome.status == 'planned' and outcome.start == here
    assert spin_until(executor, lambda: len(rig.paths) == 2)
    points = points_of(rig.paths[1])
    np.testing.assert_allclose(points[[0, -1]], [here, GOAL], atol=1e-12)
    assert violations(points, [OBSTACLE.bounds], ALERT_MARGIN) == []


def test_ball_positions_in_another_frame_are_not_used(executor):
    rig = Rig(executor)
    ball = PointStamped()
    ball.header.frame_id = 'camera'
    ball.point.x, ball.point.y, ball.point.z = (0.0, 0.12, 0.71)
    pub_count = rig.ball_pub
    assert spin_until(executor, lambda: (pub_count.publish(ball),
                                         rig.planner.problems.counts.get('ball_position'))[1])
    assert "frame_id 'camera' is not 'sra_mount'" in rig.planner.problems.last['ball_position']
    assert rig.planner.position is None
    response = rig.call(START, GOAL, frame_id='')  # GetPlan poses without a frame
    assert response.plan.poses == []
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'rejected' and "frame_id '' is not 'sra_mount'" in outcome.message


def test_a_plan_for_replaced_obstacles_is_dropped_for_the_replan(executor):
    rig = Rig(executor)
    node = rig.planner
    stale = node.run(node.job(PlanQuery(START, GOAL, 0.01), 'plan_request'))  # no obstacles
    assert stale.outcome.status == 'planned'
    assert violations(stale.planned.trajectory.points, [OBSTACLE.bounds], 0.0) != []
    rig.obstacles()  # the replan of the last request starts
    assert spin_until(executor, lambda: len(node.model.obstacles) == 1)
    assert node.publish_result(stale) is None  # computed for the old obstacles: not published
    outcome = rig.wait_outcomes(1)
    assert outcome.status == 'planned'
    assert spin_until(executor, lambda: len(rig.paths) == 1)
    assert violations(points_of(rig.paths[0]), [OBSTACLE.bounds], ALERT_MARGIN) == []
    rig.spin(0.2)
    assert len(rig.paths) == 1 and len(rig.outcomes) == 1
