"""dualarm: humanoid dual-arm motion papers as runnable, recorded, repeatable experiments.

The import package is ``pipeline``; its sub-packages follow the data flow
task -> reference -> joint path -> timed trajectory -> smoothed trajectory -> executed log:

- :mod:`pipeline.model`   robot description, CasADi kinematics, S-R-S geometry
- :mod:`pipeline.tasks`   task files (TOML) and their validation
- :mod:`pipeline.paths`   the path stage: task -> :class:`~pipeline.paths.CartesianReference`
- :mod:`pipeline.record`  MCAP / Rerun recording, run directories, reading runs back to pandas
- :mod:`pipeline.execute` PyBullet world (used by ``robot check`` and, later, execution)
"""

__version__ = "0.1.0"
