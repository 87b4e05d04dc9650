"""The PyBullet world the robot lives in: table, Franka Panda and the scene's blocks.

`World` owns one DIRECT client; everything else (GAMP, the twin, registration)
takes a World and passes its client explicitly. pybullet itself is imported
lazily, inside the functions that need it, because importing it prints a banner
on stdout.
"""

from rad_core.sim.world import World, WorldConfig

__all__ = ['World', 'WorldConfig']
