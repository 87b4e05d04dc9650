"""The problem's vocabulary: blocks, the voxel grid, scenes, targets and the shapes that make them.

The bottom of the ladder: imports nothing else of rad_core. numpy only."""
