"""The robots shipped with dualarm: one folder per robot (robot.toml and its URDF).

A package only so that the wheel carries it as ``dualarm.data.robots``; see :mod:`dualarm.data`."""
