"""The /allocate service: CP-SAT allocation of a scene (the paper's Sec. IV-A).

Parameters: time_limit_s, seed, num_workers (CP-SAT), support ('none': the paper's
MILP, the default; 'stable': every allocated block can rest on something) and
prefer ('none' or 'fewer'); a request may set support, prefer and no-goods
(exclude) of its own: the assembly node re-allocates through this service.

Every failure comes back as success=false with a reason; the node keeps serving.
"""

from __future__ import annotations

import math

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.cpsat import PREFER_MODES, SUPPORT_MODES
from rad_core.domain.errors import RadError
from rad_msgs.srv import Allocate
from rad_ros.conversions import fill_allocation_response, placement_from_msg, scene_from_request
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare, on_set
from rclpy.node import Node

PARAMS = [Param('time_limit_s', 10.0, "CP-SAT's time limit when a request gives none (s)", True),
          Param('seed', 0, "CP-SAT's random seed", True),
          Param('num_workers', 1, "CP-SAT's search workers (1..64)", True),
          Param('support', 'none', f"the support rule when a request gives none: {', '.join(SUPPORT_MODES)}", True),
          Param('prefer', 'none', f"what to prefer among equal covers: {', '.join(PREFER_MODES)}", True),
          Param('effector', 'hand', 'hand or suction, when a request gives none', True)]
NAMES = [p.name for p in PARAMS]
"""Every parameter applies to the next request; a value AllocationParams does not take is refused."""


class AllocationNode(Node):
    def __init__(self):
        super().__init__('allocation')
        declare(self, PARAMS)
        self.params_for(0.0)          # the values given at start, checked (RadError: the node does not start)
        on_set(self, self.check)
        self.service = self.create_service(Allocate, 'allocate', self.allocate_callback)
        self.get_logger().info('allocation service ready')

    def check(self, changes: dict) -> None:
        """A change of the defaults, as the next request would use them; RadError refuses it."""
        current = {name: self.get_parameter(name).value for name in NAMES}
        AllocationParams(**{**current, **changes}).validate()

    def params_for(self, request_time_limit: float, support: str = '', prefer: str = '',
                   effector: str = '') -> AllocationParams:
        for name, value, modes in (('support', support, SUPPORT_MODES), ('prefer', prefer, PREFER_MODES)):
            if value and value not in modes:
                raise RadError(f'{name} must be one of {", ".join(modes)} or empty (the node\'s), got {value!r}')
        limit = request_time_limit
        if not math.isfinite(limit) or limit < 0:
            raise RadError(f'time_limit_s must be 0 (node default) or a positive number of seconds, got {limit}')
        if limit == 0:
            limit = self.get_parameter('time_limit_s').value
        params = AllocationParams(time_limit_s=float(limit), seed=int(self.get_parameter('seed').value),
                                  num_workers=int(self.get_parameter('num_workers').value),
                                  support=support or str(self.get_parameter('support').value),
                                  prefer=prefer or str(self.get_parameter('prefer').value),
                                  effector=effector or str(self.get_parameter('effector').value))
        params.validate()
        return params

    def allocate_callback(self, request, response):
        try:
            params = self.params_for(request.time_limit_s, request.support, request.prefer, request.effector)
            scene = scene_from_request(request.scene, request.scene_json)
            result = solve(scene, params, [placement_from_msg(p) for p in request.exclude])
        except RadError as e:
            response.success, response.reason, response.status = False, str(e), 'INVALID_REQUEST'
            self.get_logger().warning(f'allocate refused: {e}')
            return response
        except Exception as e:  # noqa: BLE001 - a service must answer, never die
            self.get_logger().error(f'allocate failed: {type(e).__name__}: {e}')
            response.success, response.reason, response.status = False, f'internal error: {e}', 'ERROR'
            return response
        fill_allocation_response(response, result)
        self.get_logger().info(f'allocated {len(result.placements)} poses: {result.status}, '
                               f'objective {result.objective:g}, {result.solve_time_s * 1e3:.1f} ms')
        return response


main = main_for(AllocationNode)
