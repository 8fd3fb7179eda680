"""Analytic IK: IK-Geo's subproblems, MC-Inverse (one pose, along a path), ikfast-style, and SEW IK (one pose, along a path)."""
