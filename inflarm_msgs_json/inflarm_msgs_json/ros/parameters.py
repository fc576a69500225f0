"""Parameters declared from one table: every one with a description, a type fixed by its
default, a range where bounded, and read-only when it is structural.

Usage in a node constructor::

    PARAMETERS = (
        Parameter('rate_hz', 50.0, 'publishing rate [Hz]', range=(0.1, 1000.0)),
        Parameter('joint_names', ['joint_1'], 'joint names', read_only=True),
    )
    self.params = declare_parameters(self, PARAMETERS)   # {'rate_hz': 50.0, ...}

rclpy then rejects runtime sets of the wrong type, out of range or read-only
(``SetParametersResult(successful=False)``). The returned dict follows accepted runtime sets; a
node that checks relations between parameters, or derives state from them, says so once::

    self.params = declare_parameters(self, PARAMETERS, check=check_rates,
                                     on_set=self.on_parameters_set)
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


def declare_parameters(node: Node, parameters: tuple[Parameter, ...],
                       check: Callable[[dict[str, Any]], Any] | None = None,
                       on_set: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Declare ``parameters`` on ``node``; return their values (overrides applied), kept current.

    After every accepted runtime set the returned dict holds the new values, then
    ``on_set(changed)`` gets the ones that changed (name -> value), for what the node derives
    from them. ``check`` gets the current values with the proposed ones applied, so it can check
    relations between parameters: it returns why they are wrong (a str) or raises ValueError
    naming what is wrong; any other result (None, or the configuration it built from them)
    accepts them. A rejected set changes nothing, and its reason is the set's answer.
    """
    values = {p.name: node.declare_parameter(p.name, p.default, p.descriptor()).value
              for p in parameters}

    def validate(proposed_parameters) -> SetParametersResult:
        proposed = {**values, **{q.name: q.value for q in proposed_parameters}}
        try:
            result = check(proposed)
        except ValueError as err:
            result = str(err)
        problem = result if isinstance(result, str) else None
        return SetParametersResult(successful=problem is None, reason=problem or '')

    def apply(accepted_parameters) -> None:
        changed = {q.name: q.value for q in accepted_parameters if q.name in values}
        values.update(changed)
        if changed and on_set is not None:
            on_set(changed)

    if check is not None:
        node.add_on_set_parameters_callback(validate)
    node.add_post_set_parameters_callback(apply)
    return values
