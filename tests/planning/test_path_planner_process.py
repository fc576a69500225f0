"""path_planner as a real process: plans over DDS on its worker thread and stops cleanly."""

from nav_msgs.msg import Path
import numpy as np
import pytest
import rclpy
from std_msgs.msg import String

from inflarm_msgs_json import ObstacleSet, PlanRequest, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import LATCHED_QOS, RELIABLE_QOS
from inflarm_planning.scenario import GOAL, OBSTACLE, START
from ros_harness import spin_until

pytestmark = pytest.mark.system


def test_the_executable_plans_and_exits_cleanly(node_processes, executor):
    node_processes.start('inflarm_planning', 'path_planner')
    probe = rclpy.create_node('probe', context=executor.context)
    paths, outcomes = [], []
    probe.create_subscription(Path, 'planned_path', paths.append, LATCHED_QOS)
    probe.create_subscription(String, '/path_planner/plan_outcome',
                              lambda m: outcomes.append(decode(m.data)), LATCHED_QOS)
    obstacles = probe.create_publisher(String, 'obstacles', LATCHED_QOS)
    requests = probe.create_publisher(String, 'plan_request', RELIABLE_QOS)
    executor.add_node(probe)
    assert node_processes.wait_for_output('ready:', timeout_s=30.0), node_processes.output()
    obstacles.publish(to_string_msg(ObstacleSet('sra_mount', 0.03, (OBSTACLE.to_message(),))))
    assert spin_until(executor, lambda: requests.get_subscription_count() == 1, 15.0)
    assert node_processes.wait_for_output('1 obstacles', timeout_s=15.0), node_processes.output()
    requests.publish(to_string_msg(PlanRequest('sra_mount', START, GOAL, 0.005)))
    assert spin_until(executor, lambda: paths and outcomes, timeout_s=30.0), (
        node_processes.output())
    assert outcomes[-1].status == 'planned'
    ends = [[p.pose.position.x, p.pose.position.y, p.pose.position.z]
            for p in paths[-1].poses[::len(paths[-1].poses) - 1]]
    np.testing.assert_allclose(ends, [START, GOAL], atol=1e-12)
