"""The smooth stage: a timed joint trajectory -> a jerk-limited one at the control period (Ruckig)."""
