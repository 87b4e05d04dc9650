"""Parameters as ROS 2 tools expect them: described, ranged, and read-only unless a change applies.

Each node declares its parameters with a `ParameterDescriptor`: a description `ros2 param describe`
prints, a range where there is one (rclpy refuses a value outside it, naming the range), and
`read_only` for every value the node reads only when it starts (a `ros2 param set` on it is
refused instead of reporting success and changing nothing). Values that can change while the node
runs go through an on-set callback that applies them or refuses them with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult

from rad_core.domain.errors import RadError


@dataclass(frozen=True)
class Param:
    """One parameter: its default, what it means, and whether it can change while the node runs
    (`dynamic`; otherwise read-only), with an inclusive range for numbers."""

    name: str
    default: Any
    description: str = ''
    dynamic: bool = False
    range: tuple | None = None
    any_type: bool = False
    """Typed by what the user writes ([0, 0, 1] as well as [0.0, 0.0, 1.0]); the node checks the value."""

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description, read_only=not self.dynamic,
                                dynamic_typing=self.any_type)
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
            else:
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        return d


def declare(node, params: list[Param]) -> None:
    """Declare the parameters on a node."""
    for p in params:
        node.declare_parameter(p.name, p.default, p.descriptor())


def on_set(node, apply: Callable[[dict], None]) -> None:
    """Call `apply({name: value})` for every accepted change of the node's parameters; a RadError it
    raises refuses the change, its message the reason `ros2 param set` prints."""

    def callback(changes) -> SetParametersResult:
        try:
            apply({p.name: p.value for p in changes})
        except RadError as e:
            return SetParametersResult(successful=False, reason=str(e))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(callback)
