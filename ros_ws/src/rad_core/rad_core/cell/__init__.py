"""The robot cell as data: the Franka's model and limits, trajectories and motions, its URDF,
hand-eye calibration and motion capture. Imports `domain` only."""
