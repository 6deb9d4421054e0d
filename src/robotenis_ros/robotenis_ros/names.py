"""
Names every RoboTenis node agrees on.

The joints are the three motors in leg order (the calibration paper's i = 1, 2, 3); the base frame
is the paper's Sigma_0 (origin at the base centre, x toward motor 1, z down into the workspace).
The camera's optical frame is named by the robot description (``camera.frame_id``).
"""

JOINTS = ('motor_1', 'motor_2', 'motor_3')
BASE_FRAME = 'base'
