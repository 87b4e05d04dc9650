"""The assembly MDP (`mdp`) and its robot-in-the-loop form (`robot_env`: GAMP, the twin, physics).
Imports `domain`, `cell`, `sim` and `gamp`."""
