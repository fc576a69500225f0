"""Parameters declared from one table: every one with a description, a type fixed by its
default, a range where bounded, and read-only when it is structural.

Usage in a node constructor::

    PARAMETERS = (
        Parameter('rate_hz', 50.0, 'publishing rate [Hz]', range=(0.1, 1000.0)),
        Parameter('joint_names', ['joint_1'], 'joint names', read_only=True),
    )
    self.params = declare_parameters(self, PARAMETERS)   # {'rate_hz': 50.0, ...}

rclpy then rejects runtime sets of the wrong type, out of range or read-only
(``SetParametersResult(successful=False)``); a node validates relations between parameters with
`check_parameter_sets` and applies accepted values in a post-set callback.
"""

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.node import Node


@dataclass(frozen=True)
class Parameter:
    """One parameter's declaration. Declare floats as floats (``1.0``, not ``1``)."""

    name: str
    default: Any
    description: str
    range: tuple[float, float] | None = None  # inclusive bounds
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        descriptor = ParameterDescriptor(
            name=self.name, description=self.description, read_only=self.read_only
        )
        if self.range is not None:
            low, high = self.range
            if isinstance(self.default, float):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=float(low), to_value=float(high))
                ]
            elif isinstance(self.default, int) and not isinstance(self.default, bool):
                descriptor.integer_range = [
                    IntegerRange(from_value=int(low), to_value=int(high), step=1)
                ]
            else:
                raise TypeError(f"parameter '{self.name}': a range needs a float or int default")
        return descriptor


def declare_parameters(node: Node, parameters: tuple[Parameter, ...]) -> dict[str, Any]:
    """Declare ``parameters`` on ``node`` and return their values (overrides applied)."""
    return {
        p.name: node.declare_parameter(p.name, p.default, p.descriptor()).value
        for p in parameters
    }


def check_parameter_sets(node: Node, values: dict[str, Any],
                         check: Callable[[dict[str, Any]], Any]) -> None:
    """Reject a runtime set of ``node``'s parameters that ``check`` finds fault with.

    ``check`` gets the node's current ``values`` (the dict `declare_parameters` returned, kept
    current by the node's post-set callback) with the proposed ones applied, so it can check
    relations between parameters. It returns why they are wrong (a str) or raises ValueError
    naming what is wrong; any other result (None, or the configuration it built from them)
    accepts them. A rejected set changes nothing, and its reason is the set's answer.
    """
    def on_set(parameters) -> SetParametersResult:
        proposed = {**values, **{q.name: q.value for q in parameters}}
        try:
            result = check(proposed)
        except ValueError as err:
            result = str(err)
        problem = result if isinstance(result, str) else None
        return SetParametersResult(successful=problem is None, reason=problem or '')

    node.add_on_set_parameters_callback(on_set)
