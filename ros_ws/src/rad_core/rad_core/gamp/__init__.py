"""Grasp and motion planning (GAMP, the paper's Sec. IV-C) over a sim.World.

Composable pieces: `grasps` (which top-down grasps a block type offers), `ik`
(checked, reseeded IK for top-down hand poses), `collision` (probe callables
built over a World), `trajectory` (timing the waypoints within a
Franka's limits into a `rad_core.cell.motion.Motion` of arm trajectories and gripper
commands) and `planner` (`plan_action`: a feasible grasp/placement pair and the
motion, or the paper's failure class with a reason).
"""

from rad_core.cell.motion import GripperCommand, Motion
from rad_core.cell.trajectory import Trajectory, TrajectoryPoint
from rad_core.gamp.grasps import Grasp, block_grasps
from rad_core.gamp.ik import IkConfig, IkResult, solve_pose, solve_top_down
from rad_core.gamp.planner import GampConfig, GampResult, allocated_pose, placement_pose, plan_action
from rad_core.gamp.trajectory import TimingConfig, plan_motion, retime

__all__ = ['GampConfig', 'GampResult', 'Grasp', 'GripperCommand', 'IkConfig', 'IkResult', 'Motion', 'TimingConfig',
           'Trajectory', 'TrajectoryPoint', 'allocated_pose', 'block_grasps', 'placement_pose', 'plan_action',
           'plan_motion', 'retime', 'solve_pose', 'solve_top_down']
