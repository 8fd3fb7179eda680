"""The retime stage: a joint path -> a timed joint trajectory within velocity and acceleration limits (TOPP-RA)."""
