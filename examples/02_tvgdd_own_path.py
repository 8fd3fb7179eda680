"""TV-GDD on a path of one's own, without a task file: the left hand draws a 10 cm circle in 4 s."""

import numpy as np

import dualarm

robot = dualarm.load_robot("humanoid")
q0 = robot.home("ready")
start = dualarm.hand_pose(robot, "left", q0)  # 4x4, robot base frame [m]

period_s = 0.01  # the one control period: TV-GDD steps at the reference's period
tau = np.linspace(0.0, 1.0, 401)
angle = 2 * np.pi * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)  # rest to rest
poses = np.repeat(start[None], len(tau), axis=0)
poses[:, 1, 3] += 0.05 * np.sin(angle)  # a circle in the y-z plane through the start
poses[:, 2, 3] += 0.05 * (1 - np.cos(angle))

reference = dualarm.CartesianReference.from_poses(period_s, {"left": poses})
path = dualarm.solve_tvgdd(robot, reference, q0, dualarm.TvgddSettings(scheme="mvn"))
print(f"{len(path)} samples, joints {path.joint_names[0]}..{path.joint_names[-1]}")
print(f"largest hand position error: {path.hand_error_m.max():.2e} m")
