"""MC-Inverse for one hand pose: the 8 closed-form candidates at an arm angle, and the one nearest a seed."""

import numpy as np

import dualarm

robot = dualarm.load_robot("humanoid")  # a shipped robot, or a directory with robot.toml
ready = robot.home("ready")  # joint name -> value [rad]
pose = dualarm.hand_pose(robot, "left", ready)  # 4x4 in the robot's base frame [m]
pose[:3, 3] += [0.05, -0.05, 0.10]  # somewhere else

solution = dualarm.mc_inverse(robot, "left", pose, psi=-0.8)  # arm angle of eq (1) [rad]
for q, reason in zip(solution.q, solution.reasons, strict=True):
    print(np.round(q, 3), reason)

q = solution.nearest(ready)  # the branch MC-Inverse keeps along a path
reached = dualarm.hand_pose(robot, "left", {**ready, **dict(zip(solution.joint_names, q, strict=True))})
print("nearest:", np.round(q, 3), "position error [m]:", np.linalg.norm(reached[:3, 3] - pose[:3, 3]))
