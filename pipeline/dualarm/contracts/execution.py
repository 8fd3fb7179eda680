"""``ExecutionLog``: what the simulator did, step by step, and the contacts it saw."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

import numpy as np

from dualarm.arrays import frozen
from dualarm.contracts.verdict import Violation


@dataclass(frozen=True)
class ContactEvent:
    """One pair of bodies touching in one physics step.

    Attributes:
        t_s: the step's end time [s].
        rep: the repetition index at that time.
        first: a robot link or an object (the pair sorted by name).
        second: the other.
        depth_m: the deepest penetration between them in the step [m] (their shapes overlap: see
            :func:`~dualarm.sim.world.in_contact`).
        expected: the task expects this pair to touch (``expected_contacts``).
    """

    t_s: float
    rep: int
    first: str
    second: str
    depth_m: float
    expected: bool


@dataclass(frozen=True)
class PairContact:
    """Every step in which one pair of bodies touched, summed up.

    Attributes:
        first: a robot link or an object (sorted by name).
        second: the other.
        expected: the task expects this pair to touch.
        first_t_s: the end time of the first step in which they touched [s].
        depth_max_m: the deepest penetration over those steps [m].
        steps: how many steps they touched in.
    """

    first: str
    second: str
    expected: bool
    first_t_s: float
    depth_max_m: float
    steps: int


@dataclass(frozen=True)
class ExecutionLog:
    """What the simulator did.

    Attributes:
        joint_names: the driven joints, the columns of ``q``.
        t: 0, where the motion starts (measured before any step), then each step's end time (K,) [s].
        q: measured joint positions (K, n) [rad].
        qd: measured joint velocities (K, n) [rad/s].
        q_command: the trajectory's positions at ``t`` (K, n) [rad].
        rep: repetition index (K,).
        hand_poses: per hand, the measured hand link pose in the world (K, 4, 4) [m].
        self_contacts: unexpected robot-robot contact points per step (K,).
        environment_contacts: unexpected robot-environment contact points per step (K,).
        expected_contacts: contact points of the expected pairs per step (K,).
        contact_events: every pair touching in every step, in time order (expected pairs included).
        fixed: values of the locked joints [rad].
        preflight: what the validation before execution found in a trajectory played anyway.
        approach: the log of the approach played before the trajectory (its own clock), if any.
        hand_error_m: per hand, the distance between the measured hand position and the forward
            kinematics of the commanded joints (K,) [m] (filled by the execute stage).
    """

    joint_names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_command: np.ndarray
    rep: np.ndarray
    hand_poses: Mapping[str, np.ndarray]
    self_contacts: np.ndarray
    environment_contacts: np.ndarray
    expected_contacts: np.ndarray
    contact_events: tuple[ContactEvent, ...] = ()
    fixed: Mapping[str, float] = field(default_factory=dict)
    preflight: tuple[Violation, ...] = ()
    approach: ExecutionLog | None = None
    hand_error_m: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        K, n = len(self.t), len(self.joint_names)
        for name, shape, dtype in (
            ("t", (K,), float),
            ("q", (K, n), float),
            ("qd", (K, n), float),
            ("q_command", (K, n), float),
            ("rep", (K,), int),
            ("self_contacts", (K,), int),
            ("environment_contacts", (K,), int),
            ("expected_contacts", (K,), int),
        ):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name, dtype))
        object.__setattr__(
            self,
            "hand_poses",
            MappingProxyType({h: frozen(p, (K, 4, 4), f"hand_poses[{h}]") for h, p in self.hand_poses.items()}),
        )
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))
        object.__setattr__(
            self,
            "hand_error_m",
            MappingProxyType({h: frozen(e, (K,), f"hand_error_m[{h}]") for h, e in self.hand_error_m.items()}),
        )
        object.__setattr__(self, "contact_events", tuple(self.contact_events))

    @cached_property
    def contacts(self) -> tuple[PairContact, ...]:
        """Each pair that touched, in the order of its first contact.

        Summed up from :attr:`contact_events` once.
        """
        pairs: dict[tuple[str, str], PairContact] = {}
        for e in self.contact_events:
            seen = pairs.get((e.first, e.second))
            if seen is None:
                pairs[(e.first, e.second)] = PairContact(e.first, e.second, e.expected, e.t_s, e.depth_m, 1)
            else:
                pairs[(e.first, e.second)] = PairContact(
                    e.first, e.second, e.expected, seen.first_t_s, max(seen.depth_max_m, e.depth_m), seen.steps + 1
                )
        return tuple(pairs.values())
