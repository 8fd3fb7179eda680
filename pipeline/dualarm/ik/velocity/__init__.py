"""Velocity-level IK: TV-GDD and the pseudoinverse baseline.

TV-GDD (:mod:`.tvgdd`, its gesture bounds :mod:`.gesture` and hand stack :mod:`.stack`) and the pseudoinverse
baseline (:mod:`.pinv`).
"""
