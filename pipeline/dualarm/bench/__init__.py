"""``dualarm bench``: speed measured as ratios against peers run in the same process.

Never used by the test suite: wall-clock numbers depend on the machine. One module per
benchmark: :mod:`.tvgdd` (the TV-GDD QP step), :mod:`.ik` (single-pose IK solvers).
"""
