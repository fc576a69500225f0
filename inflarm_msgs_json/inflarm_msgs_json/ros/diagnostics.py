"""Diagnostics at about 1 Hz, aggregated between publications (as diagnostic_updater does).

    self.diagnostics = DiagnosticsPublisher(self, self.diagnostic_status)

    def diagnostic_status(self) -> list[DiagnosticStatus]:
        return [diagnostic_status('load_estimator: estimates', 'inflatable_arm', OK, 'ok',
                                  samples=self.samples, converged=self.converged)]
"""

from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from inflarm_msgs_json.ros.qos import RELIABLE_QOS

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE
DEFAULT_PERIOD_S = 1.0


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      **values: object) -> DiagnosticStatus:
    """A DiagnosticStatus whose key-value pairs are ``values`` (floats to 4 significant digits)."""
    return DiagnosticStatus(
        name=name, hardware_id=hardware_id, level=level, message=message,
        values=[KeyValue(key=key, value=f'{v:.4g}' if isinstance(v, float) else str(v))
                for key, v in values.items()])


class DiagnosticsPublisher:
    """Publishes ``status()`` on ``diagnostics`` every ``period_s`` from a guarded timer of the
    node (a `GuardedCallbacks` node)."""

    def __init__(self, node, status: Callable[[], list[DiagnosticStatus]],
                 period_s: float = DEFAULT_PERIOD_S) -> None:
        self.node = node
        self.status = status
        self.publisher = node.create_publisher(DiagnosticArray, 'diagnostics', RELIABLE_QOS)
        self.timer = node.create_guarded_timer(period_s, self.publish, 'diagnostics')

    def publish(self) -> None:
        array = DiagnosticArray(status=self.status())
        array.header.stamp = self.node.get_clock().now().to_msg()
        self.publisher.publish(array)
