"""The README's topic and parameter tables, from the nodes themselves: every topic the launched
systems use (``sim`` on the simulators and on the bridge with its simulated MCU), its type, the
QoS its endpoints use, its publishers and subscribers; every parameter of those nodes, its value
as launched and its description. ``python tests/interface_table.py [domain]`` prints both."""

import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from inflarm_bringup.launcher import node_class
from inflarm_bringup.systems import Backend, system_nodes

HIDDEN = {'/parameter_events', '/rosout', '/clock'}  # rclpy's own


def qos_text(profile) -> str:
    reliability = 'reliable' if profile.reliability == ReliabilityPolicy.RELIABLE else (
        'best effort')
    latched = ', latched' if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL else ''
    return f'{reliability}{latched}, last {profile.depth}'


def type_name(msg_type) -> str:
    return f'{msg_type.__module__.split(".")[0]}/{msg_type.__name__}'


ROS_OWN_PARAMETERS = {'use_sim_time', 'start_type_description_service'}
MAX_VALUE_CHARS = 48


def value_text(value, mcu_link: str) -> str:
    value = value.tolist() if hasattr(value, 'tolist') else value  # array.array of rclpy
    text = repr(value).replace(mcu_link, '<port>')  # the launcher's pty for this run
    if isinstance(value, str):
        text = f"'{value}'" if '<port>' not in text else '<port>'
    text = text if len(text) <= MAX_VALUE_CHARS else text[:MAX_VALUE_CHARS - 3] + '...'
    return text.replace('|', '\\|')


def interface_rows(domain_id: int, mcu_link: str) -> tuple[list[str], list[str]]:
    """Markdown rows ``| topic | type | QoS | published by | subscribed by |`` and
    ``| nodes | parameter | value as launched | description |``."""
    specs = {n.node_name: n for systems in (
        system_nodes('sim'), system_nodes('sim', Backend('sim_mcu', mcu_link))) for n in systems}
    arguments = ['interface-table', '--ros-args']
    for spec in specs.values():
        for path in spec.parameter_files():
            if path not in arguments:
                arguments += ['--params-file', path]
    context = rclpy.Context()
    rclpy.init(args=arguments, context=context, domain_id=domain_id)
    topics: dict[str, dict] = {}
    parameters: dict[tuple, list[str]] = {}  # (name, value, description) -> nodes
    nodes = []
    try:
        for spec in specs.values():
            nodes.append(node := node_class(spec)(context=context, parameter_overrides=[
                Parameter(k, value=v) for k, v in {**spec.parameters, 'autostart': False}.items()
                if spec.executable == 'hw_bridge' or k != 'autostart']))
            if spec.executable == 'hw_bridge':  # its topics come with configure, on the MCU
                mcu = SingleThreadedExecutor(context=context)
                mcu.add_node(next(n for n in nodes if n.get_name() == 'sim_mcu'))
                spinning = threading.Thread(target=mcu.spin, daemon=True)
                spinning.start()
                node.trigger_configure()
                mcu.shutdown()
                spinning.join()
            for kind, entities in (('pub', node.publishers), ('sub', node.subscriptions)):
                for entity in entities:
                    if entity.topic_name in HIDDEN:
                        continue
                    entry = topics.setdefault(entity.topic_name, {
                        'type': type_name(entity.msg_type), 'qos': set(), 'pub': set(),
                        'sub': set()})
                    entry['qos'].add(qos_text(entity.qos_profile))
                    entry[kind].add(spec.node_name)
            for name in sorted(node.list_parameters([], 0).names):
                if name in ROS_OWN_PARAMETERS:
                    continue
                description = node.describe_parameter(name).description.replace('|', '\\|')
                launched = spec.parameters.get(name, node.get_parameter(name).value)
                value = value_text(launched, mcu_link)
                parameters.setdefault((name, value, description), []).append(spec.node_name)
    finally:
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.shutdown(context=context)
    rows = []
    for topic, entry in sorted(topics.items()):
        rows.append(f'| `{topic.lstrip("/")}` | {entry["type"]} | '
                    f'{"; ".join(sorted(entry["qos"]))} | {", ".join(sorted(entry["pub"]))} | '
                    f'{", ".join(sorted(entry["sub"]))} |')
    # A parameter shared alike by several nodes (arm.*, camera.*) is one row.
    parameter_rows = [
        f'| {", ".join(f"`{n}`" for n in nodes)} | `{name}` | `{value}` | {description} |'
        for (name, value, description), nodes in parameters.items()]
    return rows, parameter_rows


if __name__ == '__main__':
    import sys
    import tempfile
    with tempfile.TemporaryDirectory() as directory:
        topics, parameters = interface_rows(int(sys.argv[1]) if len(sys.argv) > 1 else 101,
                                            f'{directory}/mcu')
        print('\n'.join(topics + [''] + parameters))
