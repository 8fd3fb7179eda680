"""Pose-level IK, one pose at a time along a path.

DLS-SVD (:mod:`.dls`), the TRAC-IK and PyBullet baselines (:mod:`.baselines`) and the driver
(:mod:`.pointwise`).
"""
