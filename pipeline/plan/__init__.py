"""Collision-avoiding dual-arm planning (Li & Liang): Workspace Target Areas, collision checking,
MCIKRRT and the OMPL RRTConnect baseline."""

#: The planners of the plan stage (kept here, so that naming one imports nothing heavy).
PLANNERS = ("mcikrrt", "ompl-rrtconnect")
