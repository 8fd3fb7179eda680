"""Inverse kinematics: Cartesian reference -> joint path (TV-GDD, pseudoinverse, ...)."""
