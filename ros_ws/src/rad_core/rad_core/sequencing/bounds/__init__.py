"""What any order could build: the allocation's ceiling without the robot (`ceiling`) and the
robot-feasible ceiling (`robot_ceiling`)."""
