"""The paper tasks shipped with dualarm: one TOML file per experiment (see README.md here).

A package only so that the wheel carries it as ``dualarm.data.tasks``; see :mod:`dualarm.data`."""
