"""A run's verdict (``complete``, ``violated`` or ``failed``), and the checks it failed.

And the bounds it is judged against.

How each stage's product is judged is :mod:`dualarm.violations`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Literal

Status = Literal["complete", "violated", "failed"]
#: The command line's exit code for each verdict.
EXIT_CODES: Mapping[str, int] = {"complete": 0, "violated": 3, "failed": 1}


@dataclass(frozen=True)
class Checks:
    """The bounds a run is judged against.

    Attributes:
        ik_position_tolerance_m: largest hand position error of an IK sample [m].
        ik_orientation_tolerance_rad: largest hand orientation error of an IK sample, when the
            method was asked for the orientation [rad].
        tracking_bound_m: largest distance between a measured hand position and the forward
            kinematics of the commanded joints during execution [m].
    """

    ik_position_tolerance_m: float = 1e-3
    ik_orientation_tolerance_rad: float = 1e-2
    tracking_bound_m: float = 0.01


@dataclass(frozen=True)
class Violation:
    """A failed check.

    Attributes:
        check: ``ik``, ``limit``, ``contact`` or ``tracking``.
        stage: the stage whose product failed it.
        message: one line: what, where and when.
        t_s: the first time it occurs [s] (motion time; None when it has none).
    """

    check: str
    stage: str
    message: str
    t_s: float | None = None

    def as_record(self) -> dict[str, object]:
        """JSON-ready fields (a manifest's ``violations``)."""
        return asdict(self)


@dataclass(frozen=True)
class Verdict:
    """How a run ended.

    Attributes:
        status: ``complete``, ``violated`` or ``failed``.
        violations: the failed checks, earliest stage first (empty for ``complete``).
        error: why a ``failed`` run failed (None otherwise).
    """

    status: Status
    violations: tuple[Violation, ...] = ()
    error: str | None = None

    @classmethod
    def of(cls, violations: Sequence[Violation]) -> Verdict:
        """``violated`` with ``violations``, or ``complete`` without any.

        Each message once: the execute stage's preflight re-checks the smoothed trajectory.
        """
        unique = tuple({v.message: v for v in violations}.values())  # dicts keep the first insertion's place
        return cls("violated" if unique else "complete", unique)

    @classmethod
    def failure(cls, error: str, violations: Sequence[Violation] = ()) -> Verdict:
        """``failed`` because of ``error``."""
        return cls("failed", tuple(violations), error)

    @property
    def exit_code(self) -> int:
        """The command line's exit code (:data:`EXIT_CODES`)."""
        return EXIT_CODES[self.status]

    @property
    def first(self) -> str:
        """One line: the error of a failed run, the first violation of a violated one, else ``""``."""
        if self.error:
            return self.error
        return self.violations[0].message if self.violations else ""

    def lines(self) -> list[str]:
        """The verdict as the last lines a command prints: the status, then each violation (at most 10)."""
        more = len(self.violations) - 10
        head = f"verdict: {self.status}" + (
            f" ({len(self.violations)} violation{'s' * (len(self.violations) > 1)})" if self.violations else ""
        )
        tail = [f"... and {more} more (manifest.json: violations)"] if more > 0 else []
        return [
            head,
            *([f"error: {self.error}"] if self.error else []),
            *(f"  {v.message}" for v in self.violations[:10]),
            *tail,
        ]
