"""Analytic IK: IK-Geo's subproblems, MC-Inverse, ikfast-style, and SEW IK.

MC-Inverse and SEW IK each for one pose and along a path.
"""
