"""The simulation world: the robot and the task's objects loaded in PyBullet (DIRECT mode).

Its shapes and contacts.
"""
