"""A robot: its URDF, named kinematic chains, joint limits and home poses (``robot.toml``)."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from dualarm.errors import InvalidArgumentError, RobotModelError
from dualarm.model.urdf import JointSpec, UrdfModel, load_urdf


@dataclass(frozen=True)
class JointLimits:
    """Limits of one joint.

    Attributes:
        lower: lowest position [rad].
        upper: highest position [rad].
        velocity: largest speed [rad/s].
        acceleration: largest acceleration [rad/s^2] (inf where robot.toml gives none).
        jerk: largest jerk [rad/s^3] (inf where robot.toml gives none).
        effort: largest torque [N m].
    """

    lower: float
    upper: float
    velocity: float
    acceleration: float
    jerk: float
    effort: float


@dataclass(frozen=True)
class Chain:
    """The joints from link ``base`` down to link ``tip``.

    Attributes:
        name: chain name (``left_arm``, ``waist``, ... or ``base->tip`` for an ad-hoc chain).
        base: base link; poses of the chain are expressed in its frame.
        tip: tip link (for an arm, the hand frame).
        joints: every joint on the way, fixed ones included, from base to tip.
        hand: the hand this chain drives in tasks (``left``/``right``), or None.
    """

    name: str
    base: str
    tip: str
    joints: tuple[JointSpec, ...]
    hand: str | None = None

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Names of the movable joints, base to tip; the order of ``q``."""
        return tuple(j.name for j in self.joints if j.movable)

    @property
    def dof(self) -> int:
        """Number of movable joints."""
        return len(self.joint_names)


@dataclass(frozen=True)
class Robot:
    """A robot description.

    Attributes:
        name: robot name.
        directory: directory holding robot.toml (None for a bare URDF).
        urdf: the parsed URDF.
        chains: named chains.
        limits: limits of every movable joint, by joint name.
        homes: named home poses, each a full joint-name -> value map [rad].
        description: free text from robot.toml.
    """

    name: str
    directory: Path | None
    urdf: UrdfModel
    chains: Mapping[str, Chain]
    limits: Mapping[str, JointLimits]
    homes: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    description: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Every movable joint of the URDF, in file order."""
        return tuple(j.name for j in self.urdf.joints if j.movable)

    def chain(self, name: str) -> Chain:
        """The chain called ``name``; RobotModelError listing the valid names otherwise."""
        if name not in self.chains:
            raise RobotModelError(f"robot '{self.name}' has no chain '{name}' (chains: {', '.join(self.chains)})")
        return self.chains[name]

    def chain_between(self, base: str, tip: str) -> Chain:
        """An ad-hoc chain from link ``base`` to link ``tip``."""
        return Chain(name=f"{base}->{tip}", base=base, tip=tip, joints=self.urdf.chain(base, tip))

    def hand_chain(self, hand: str) -> Chain:
        """The arm chain that drives hand ``hand`` (``left``/``right``)."""
        for chain in self.chains.values():
            if chain.hand == hand:
                return chain
        hands = [c.hand for c in self.chains.values() if c.hand]
        raise RobotModelError(f"robot '{self.name}' has no hand '{hand}' (hands: {', '.join(hands)})")

    @property
    def hands(self) -> tuple[str, ...]:
        """Names of the hands, in chain order."""
        return tuple(c.hand for c in self.chains.values() if c.hand)

    def home(self, name: str) -> Mapping[str, float]:
        """Home pose ``name`` as joint -> value [rad]."""
        if name not in self.homes:
            raise RobotModelError(f"robot '{self.name}' has no home pose '{name}' (homes: {', '.join(self.homes)})")
        return self.homes[name]

    def lower_upper(self, joint_names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Position limits of ``joint_names`` as two arrays [rad]."""
        return (
            np.array([self.limits[n].lower for n in joint_names]),
            np.array([self.limits[n].upper for n in joint_names]),
        )

    def limit_array(self, kind: str, joint_names: tuple[str, ...]) -> np.ndarray:
        """The ``kind`` limits (``velocity`` [rad/s], ``acceleration`` [rad/s^2], ``jerk`` [rad/s^3], ``effort`` [N m]) of ``joint_names``, (n,)."""
        return np.array([getattr(self.limits[n], kind) for n in joint_names], dtype=float)

    def with_limits(self, **overrides: float | Mapping[str, float] | None) -> "Robot":
        """The same robot with some limits replaced: ``kind=value`` for every joint, or ``kind={joint: value}`` for some (kinds ``velocity``, ``acceleration``, ``jerk``; None keeps the robot's).

        A task's ``[limits]`` table is applied so.

        Raises:
            InvalidArgumentError: an unknown kind or joint.
        """
        limits = dict(self.limits)
        for kind, value in overrides.items():
            if kind not in ("velocity", "acceleration", "jerk"):
                raise InvalidArgumentError(kind, "not a limit that can be overridden (velocity, acceleration, jerk)")
            if value is None:
                continue
            table = value if isinstance(value, Mapping) else dict.fromkeys(limits, value)
            for name, v in table.items():
                if name not in limits:
                    raise InvalidArgumentError(f"{kind}.{name}", f"no such joint in robot '{self.name}'")
                limits[name] = replace(limits[name], **{kind: float(v)})
        return replace(self, limits=MappingProxyType(limits))

    def configuration(self, q: "Mapping[str, float] | str | None" = None, name: str = "q") -> Mapping[str, float]:
        """Every movable joint's value [rad]: a home pose's name, or a mapping joint -> value (joints not named at 0), or None (all at 0).

        Raises:
            InvalidArgumentError: an unknown home or joint, a value that is not finite or is
                outside the joint's position limits.
        """
        if q is None:
            return MappingProxyType(dict.fromkeys(self.joint_names, 0.0))
        if isinstance(q, str):
            if q not in self.homes:
                raise InvalidArgumentError(name, f"robot '{self.name}' has no home pose '{q}' (homes: {', '.join(self.homes) or 'none'})")
            return self.homes[q]
        if not isinstance(q, Mapping):
            raise InvalidArgumentError(name, f"expected a home pose's name or a mapping joint name -> value, got {type(q).__name__}")
        values = dict.fromkeys(self.joint_names, 0.0)
        for joint, value in q.items():
            if joint not in self.limits:
                raise InvalidArgumentError(f"{name}.{joint}", f"no such joint in robot '{self.name}'")
            value = _number(value, f"{name}.{joint}")
            lim = self.limits[joint]
            if not lim.lower <= value <= lim.upper:
                raise InvalidArgumentError(f"{name}.{joint}", f"{value} rad outside the joint limits [{lim.lower:.4f}, {lim.upper:.4f}]")
            values[joint] = value
        return MappingProxyType(values)


def _number(value: Any, name: str) -> float:
    """``value`` as a finite float; InvalidArgumentError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not np.isfinite(value):
        raise InvalidArgumentError(name, f"expected a finite number, got {value!r}")
    return float(value)


def _limits_from_urdf(urdf: UrdfModel, acceleration: Mapping[str, float], jerk: Mapping[str, float]) -> dict[str, JointLimits]:
    return {
        j.name: JointLimits(
            lower=j.lower,
            upper=j.upper,
            velocity=j.velocity,
            acceleration=float(acceleration.get(j.name, np.inf)),
            jerk=float(jerk.get(j.name, np.inf)),
            effort=j.effort,
        )
        for j in urdf.joints
        if j.movable
    }


def robot_from_urdf(urdf_path: str | Path, base: str, tip: str) -> Robot:
    """A robot made of one chain of a bare URDF (no robot.toml): ``robot check --urdf``."""
    urdf = load_urdf(urdf_path)
    chain = Chain(name="chain", base=base, tip=tip, joints=urdf.chain(base, tip))
    return Robot(
        name=urdf.name,
        directory=None,
        urdf=urdf,
        chains=MappingProxyType({"chain": chain}),
        limits=MappingProxyType(_limits_from_urdf(urdf, {}, {})),
        homes=MappingProxyType({"zero": MappingProxyType({n: 0.0 for n in chain.joint_names})}),
    )


_TOP_KEYS = {"name", "urdf", "description", "chains", "limits", "home"}
_CHAIN_KEYS = {"base", "tip", "hand"}


def _table(data: object, where: str) -> dict:
    if not isinstance(data, dict):
        raise RobotModelError(f"{where}: expected a table")
    return data


def _unknown(data: dict, allowed: set[str], where: str) -> None:
    extra = sorted(set(data) - allowed)
    if extra:
        raise RobotModelError(f"{where}.{extra[0]}: unknown key (allowed: {', '.join(sorted(allowed))})")


def _joint_values(data: object, where: str, joints: tuple[str, ...]) -> dict[str, float]:
    values = {}
    for name, value in _table(data, where).items():
        if name not in joints:
            raise RobotModelError(f"{where}.{name}: no such joint (joints: {', '.join(joints)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise RobotModelError(f"{where}.{name}: expected a number, got {value!r}")
        values[name] = float(value)
    return values


def load_robot(directory: str | Path) -> Robot:
    """Load ``directory/robot.toml`` and the URDF it names; a bare name that is no directory here (``humanoid``) is a shipped robot (see :mod:`dualarm.data`).

    Raises:
        RobotModelError: naming ``robot.toml:key`` for anything missing or malformed.
    """
    from dualarm.data import find_robot

    directory = find_robot(directory)
    toml_path = directory / "robot.toml"
    if not toml_path.is_file():
        raise RobotModelError(f"{directory}: no robot.toml (a robot directory holds robot.toml and its URDF)")
    try:
        data = tomllib.loads(toml_path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise RobotModelError(f"{toml_path}: {exc}") from None
    where = str(toml_path)
    _unknown(data, _TOP_KEYS, where)
    for key in ("name", "urdf", "chains"):
        if key not in data:
            raise RobotModelError(f"{where}:{key}: missing")
    urdf = load_urdf(directory / str(data["urdf"]))
    movable = tuple(j.name for j in urdf.joints if j.movable)

    chains: dict[str, Chain] = {}
    for name, spec in _table(data["chains"], f"{where}:chains").items():
        spec = _table(spec, f"{where}:chains.{name}")
        _unknown(spec, _CHAIN_KEYS, f"{where}:chains.{name}")
        for key in ("base", "tip"):
            if key not in spec:
                raise RobotModelError(f"{where}:chains.{name}.{key}: missing")
        chains[name] = Chain(
            name=name,
            base=spec["base"],
            tip=spec["tip"],
            joints=urdf.chain(spec["base"], spec["tip"]),
            hand=spec.get("hand"),
        )

    limits_data = _table(data.get("limits", {}), f"{where}:limits")
    _unknown(limits_data, {"acceleration", "jerk"}, f"{where}:limits")
    acceleration = _joint_values(limits_data.get("acceleration", {}), f"{where}:limits.acceleration", movable)
    jerk = _joint_values(limits_data.get("jerk", {}), f"{where}:limits.jerk", movable)
    for key, values in (("acceleration", acceleration), ("jerk", jerk)):
        for joint, value in values.items():
            if value <= 0:
                raise RobotModelError(f"{where}:limits.{key}.{joint}: must be positive, got {value}")
    limits = _limits_from_urdf(urdf, acceleration, jerk)

    homes: dict[str, Mapping[str, float]] = {}
    for name, values in _table(data.get("home", {}), f"{where}:home").items():
        given = _joint_values(values, f"{where}:home.{name}", movable)
        for joint, value in given.items():
            lim = limits[joint]
            if not lim.lower <= value <= lim.upper:
                raise RobotModelError(f"{where}:home.{name}.{joint}: {value} outside the joint limits [{lim.lower}, {lim.upper}]")
        homes[name] = MappingProxyType({n: given.get(n, 0.0) for n in movable})

    return Robot(
        name=str(data["name"]),
        directory=directory,
        urdf=urdf,
        chains=MappingProxyType(chains),
        limits=MappingProxyType(limits),
        homes=MappingProxyType(homes),
        description=str(data.get("description", "")).strip(),
    )
