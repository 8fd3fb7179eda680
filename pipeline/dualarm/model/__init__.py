"""The robot model.

URDF and robot.toml (:mod:`.robot`), CasADi kinematics (:mod:`.kinematics`), S-R-S geometry (:mod:`.srs`),
poses and the kinematics check.
"""
