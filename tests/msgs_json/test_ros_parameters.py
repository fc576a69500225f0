"""declare_parameters: the returned values follow accepted runtime sets, then on_set gets what
changed; a set is checked with the node's other values, rejected with the check's reason, and a
rejected set changes nothing."""

import rclpy
from rclpy.parameter import Parameter as RclpyParameter

from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters

PARAMETERS = (
    Parameter('low_m', 0.1, 'lower bound [m]'),
    Parameter('high_m', 0.5, 'upper bound [m]'),
)


def ordered(values: dict) -> str | None:
    if values['low_m'] >= values['high_m']:
        return f"low_m {values['low_m']} must be below high_m {values['high_m']}"
    return None


def raising(values: dict) -> dict:
    if values['high_m'] > 1.0:
        raise ValueError(f"high_m {values['high_m']} is over 1 m")
    return values  # a configuration built from them: accepted


def node_with(check, context, on_set=None):
    node = rclpy.create_node('checked', context=context)
    return node, declare_parameters(node, PARAMETERS, check=check, on_set=on_set)


def test_on_set_gets_what_changed_after_the_values_follow_it(executor):
    seen = []
    node, values = node_with(None, executor.context,
                             on_set=lambda changed: seen.append((changed, dict(values))))
    assert node.set_parameters([RclpyParameter('high_m', value=0.8)])[0].successful
    assert seen == [({'high_m': 0.8}, {'low_m': 0.1, 'high_m': 0.8})]
    # a parameter rclpy declares itself is not one of the table's: no call
    assert node.set_parameters([RclpyParameter('use_sim_time', value=True)])[0].successful
    assert len(seen) == 1 and 'use_sim_time' not in values
    node.destroy_node()


def test_a_set_is_checked_against_the_values_it_leaves_unchanged(executor):
    node, values = node_with(ordered, executor.context)
    result = node.set_parameters([RclpyParameter('low_m', value=0.7)])[0]
    assert not result.successful
    assert result.reason == 'low_m 0.7 must be below high_m 0.5'
    assert values == {'low_m': 0.1, 'high_m': 0.5}
    assert node.get_parameter('low_m').value == 0.1
    # the same value with high_m moved in one set: checked together, accepted
    result = node.set_parameters_atomically([RclpyParameter('low_m', value=0.7),
                                             RclpyParameter('high_m', value=0.9)])
    assert result.successful, result.reason
    assert values == {'low_m': 0.7, 'high_m': 0.9}
    node.destroy_node()


def test_a_check_that_raises_names_the_problem_and_one_that_builds_accepts(executor):
    node, values = node_with(raising, executor.context)
    result = node.set_parameters([RclpyParameter('high_m', value=2.0)])[0]
    assert (result.successful, result.reason) == (False, 'high_m 2.0 is over 1 m')
    assert node.set_parameters([RclpyParameter('high_m', value=0.8)])[0].successful
    assert values['high_m'] == 0.8
    node.destroy_node()
