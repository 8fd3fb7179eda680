"""Collision-avoiding dual-arm planning (Li & Liang).

Workspace Target Areas, collision checking, MCIKRRT and the OMPL RRTConnect baseline.

The planners are listed in :data:`dualarm.methods.PLANNERS`.
"""
