"""The RViz configuration shows what the sim system publishes: every display's topic exists,
with the display's message type and a QoS its publishers can serve, in frames TF will have."""

import re

from conftest import lock_free_domain
import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
import yaml

from inflarm_bringup.launcher import node_class
from inflarm_bringup.systems import STATIC_FRAMES, rviz_config, system_nodes, visualization_nodes

DISPLAY_TYPES = {
    'rviz_default_plugins/RobotModel': 'std_msgs/msg/String',
    'rviz_default_plugins/Wrench': 'geometry_msgs/msg/WrenchStamped',
    'rviz_default_plugins/PointStamped': 'geometry_msgs/msg/PointStamped',
    'rviz_default_plugins/Path': 'nav_msgs/msg/Path',
    'rviz_default_plugins/MarkerArray': 'visualization_msgs/msg/MarkerArray',
    'rviz_default_plugins/Image': 'sensor_msgs/msg/Image',
}
RELIABILITY = {'Reliable': ReliabilityPolicy.RELIABLE,
               'Best Effort': ReliabilityPolicy.BEST_EFFORT}
DURABILITY = {'Volatile': DurabilityPolicy.VOLATILE,
              'Transient Local': DurabilityPolicy.TRANSIENT_LOCAL}


def displays(entries):
    for entry in entries:
        if entry['Class'] == 'rviz_common/Group':
            yield from displays(entry['Displays'])
        else:
            yield entry


with open(rviz_config()) as _file:
    CONFIG = yaml.safe_load(_file)['Visualization Manager']
TOPIC_DISPLAYS = [d for d in displays(CONFIG['Displays'])
                  if 'Topic' in d or 'Description Topic' in d]


def type_name(msg_type) -> str:
    module = msg_type.__module__.split('.')[0]
    return f'{module}/msg/{msg_type.__name__}'


@pytest.fixture(scope='module')
def endpoints():
    """topic -> [(kind, type, qos)] of the sim system's nodes, made in one process; and the
    frames their parameters name."""
    import rclpy
    from rclpy.parameter import Parameter

    domain, lock = lock_free_domain()
    nodes = system_nodes('sim')
    arguments = ['rviz-config-test', '--ros-args']
    for node in nodes:
        for path in node.parameter_files():
            if path not in arguments:
                arguments += ['--params-file', path]
    context = rclpy.Context()
    rclpy.init(args=arguments, context=context, domain_id=domain)
    found: dict[str, list] = {}
    frames = set()
    try:
        for spec in nodes:
            node = node_class(spec)(context=context, parameter_overrides=[
                Parameter(k, value=v) for k, v in spec.parameters.items()])
            for kind, entities in (('publisher', node.publishers),
                                   ('subscription', node.subscriptions)):
                for entity in entities:
                    found.setdefault(entity.topic_name, []).append(
                        (kind, type_name(entity.msg_type), entity.qos_profile))
            for name in ('frame_id', 'tip_frame_id'):
                if node.has_parameter(name):
                    frames.add(node.get_parameter(name).value)
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
        lock.close()
    return found, frames


@pytest.mark.parametrize('display', TOPIC_DISPLAYS, ids=lambda d: d['Name'])
def test_each_display_subscribes_to_a_topic_of_the_system_it_can_receive(display, endpoints):
    found, _ = endpoints
    topic = display.get('Topic') or display['Description Topic']
    name = topic['Value']
    assert name in found, f'{display["Name"]}: nobody in the sim system uses {name}'
    types = {t for _, t, _ in found[name]}
    assert types == {DISPLAY_TYPES[display['Class']]}, f'{name}: {types}'
    reliability = RELIABILITY[topic['Reliability Policy']]
    durability = DURABILITY[topic['Durability Policy']]
    publishers = [qos for kind, _, qos in found[name] if kind == 'publisher']
    if publishers:  # the display's reader must match every writer
        for qos in publishers:
            assert not (reliability == ReliabilityPolicy.RELIABLE
                        and qos.reliability != ReliabilityPolicy.RELIABLE), name
            assert not (durability == DurabilityPolicy.TRANSIENT_LOCAL
                        and qos.durability != DurabilityPolicy.TRANSIENT_LOCAL), name
    else:  # a client publishes it (a tip path): read it as the system's own reader does
        (reader,) = [qos for kind, _, qos in found[name] if kind == 'subscription']
        assert (reader.reliability, reader.durability) == (reliability, durability), name


def test_the_frames_the_system_publishes_in_are_on_the_tf_tree(endpoints):
    _, frames = endpoints
    state_publisher = visualization_nodes()[0]
    links = set(re.findall(r'<link name="([^"]+)"',
                           state_publisher.parameters['robot_description']))
    on_tree = {CONFIG['Global Options']['Fixed Frame']} | links | {
        child for _, child, _, _ in STATIC_FRAMES}
    assert {'base_link', 'sra_mount', 'tip'} <= frames
    assert frames <= on_tree, frames - on_tree
