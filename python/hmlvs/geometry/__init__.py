"""The physical set-up: the robot arm's kinematics (``robot``) and the checkerboard (``board``)."""
