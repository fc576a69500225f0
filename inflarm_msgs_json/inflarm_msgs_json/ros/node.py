"""Callbacks that never kill a node: the mixin every inflarm node (plain or lifecycle) uses.

    class SraSim(GuardedCallbacks, Node):
        def __init__(self, **kwargs):
            super().__init__('sra_sim', **kwargs)
            self.create_guarded_subscription(String, 'chamber_pressure_command',
                                             self.on_command, COMMAND_QOS)
            self.create_guarded_timer(0.02, self.step)

A guarded callback reports a rejected input (any ``ValueError``, e.g. `InputError`) as a warning
throttled per kind of problem, and a bug (any other exception) as an error with its traceback;
the node keeps running either way (`inflarm_msgs_json.ros.problems`). Subscriptions also log
incompatible QoS offers, which otherwise drop every message silently.
"""

import functools

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

from inflarm_msgs_json.ros.problems import ProblemReporter
from inflarm_msgs_json.ros.qos import subscription_events


class GuardedCallbacks:
    """Mixin for ``rclpy.node.Node`` and ``rclpy.lifecycle.LifecycleNode``; list it first."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.problems = ProblemReporter(self.get_logger())
        # rclpy's lifecycle services raise RCLError on a request for a transition the state
        # machine does not have (any ros2 lifecycle set typo): answered with the reason instead.
        for service in self.services:
            if service.srv_type.__module__.startswith('lifecycle_msgs'):
                service.callback = self.problems.guard_service(
                    service.srv_name, _transition_request(service.callback))

    def create_guarded_subscription(self, msg_type, topic: str, callback, qos, **kwargs):
        """``create_subscription`` whose callback is guarded under the topic's name."""
        kwargs.setdefault('event_callbacks', subscription_events(self, topic))
        return self.create_subscription(msg_type, topic, self.problems.guard(topic, callback),
                                        qos, **kwargs)

    def create_guarded_timer(self, period_s: float, callback, name: str | None = None,
                             **kwargs):
        """``create_timer`` whose callback is guarded (problems named after ``name``)."""
        source = name or getattr(callback, '__name__', 'timer')
        return self.create_timer(period_s, self.problems.guard(source, callback), **kwargs)

    def create_guarded_service(self, srv_type, name: str, callback, **kwargs):
        """``create_service``; a rejected request is answered with the reason."""
        return self.create_service(srv_type, name, self.problems.guard_service(name, callback),
                                   **kwargs)


def _transition_request(callback):
    """A lifecycle service callback whose unknown transition is a rejected request."""
    @functools.wraps(callback)
    def call(request, response):
        try:
            return callback(request, response)
        except _rclpy.RCLError as error:
            raise ValueError(str(error).split(', at ')[0]) from error
    return call
