"""The one exception hierarchy of dualarm.

Every error a user can cause derives from :class:`DualarmError`; the CLI prints its message as one
line on stderr and exits with code 2. Messages name the file, key or joint at fault.
"""


class DualarmError(Exception):
    """Base class of every error dualarm raises on purpose."""


class RobotModelError(DualarmError):
    """A robot directory, robot.toml or URDF is missing, malformed or inconsistent."""


class NotSRSError(RobotModelError):
    """A chain was required to be Spherical-Revolute-Spherical and is not."""


class TaskFileError(DualarmError):
    """A task file is missing, malformed, or asks for something the robot cannot do."""


class UnreachablePoseError(TaskFileError):
    """A hand pose of a task lies outside the arm's workspace."""


class RecordingError(DualarmError):
    """A run directory or recording is missing, incomplete or corrupt."""


class StageError(DualarmError):
    """A pipeline stage failed on valid input (the run is recorded as failed)."""
