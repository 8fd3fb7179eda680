"""A robot: its URDF, named kinematic chains, joint limits and home poses (``robot.toml``)."""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from dualarm.errors import InvalidArgumentError, RobotModelError, excerpt
from dualarm.files import listing, read_text
from dualarm.model.urdf import JointSpec, UrdfModel, load_urdf

#: The reasons robot.toml's ``[collision] disabled`` pairs may give: joined through fixed joints and joints in no chain
#: only (they never move relative to each other in a task), in contact at every configuration ``robot init``
#: sampled, or the user's word.
COLLISION_REASONS = ("rigid", "always", "user")

#: The range robot.toml's ``[limits]`` accept, per kind: (lowest, highest) [rad/s], [rad/s^2] and [rad/s^3].
#: The lowest keeps a retimed motion's duration (path length / limit) bounded, the highest is
#: beyond any actuator; both are far from the humanoid's (velocity 2-3, acceleration 4-12, jerk 40-150).
#: ``velocity`` replaces the URDF's ``<limit velocity>``; acceleration and jerk exist only here.
LIMIT_RANGES = {"velocity": (1e-3, 1e3), "acceleration": (1e-2, 1e4), "jerk": (1e-1, 1e6)}


@dataclass(frozen=True)
class JointLimits:
    """Limits of one joint.

    Attributes:
        lower: lowest position [rad].
        upper: highest position [rad].
        velocity: largest speed [rad/s] (robot.toml's ``[limits.velocity]``, else the URDF's).
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

    @cached_property
    def joint_names(self) -> tuple[str, ...]:
        """Names of the movable joints, base to tip; the order of ``q``."""
        return tuple(j.name for j in self.joints if j.movable)

    @property
    def dof(self) -> int:
        """Number of movable joints."""
        return len(self.joint_names)


@dataclass(frozen=True, eq=False)
class Robot:
    """A robot description.

    Compared and hashed by identity: a loaded robot is one object, and the solvers a process builds
    once for it (a study's worker, not once per trial) are kept by it.

    Attributes:
        name: robot name.
        directory: directory holding robot.toml (None for a bare URDF).
        urdf: the parsed URDF.
        chains: named chains.
        limits: limits of every movable joint, by joint name.
        homes: named home poses, each a full joint-name -> value map [rad].
        description: free text from robot.toml.
        assumed_limits: the limit kinds (``velocity``, ``acceleration``, ``jerk``) whose values are ``robot init``'s
            assumptions, not the robot's data (robot.toml's ``[limits] assumed``): messages they cause say so.
        disabled_pairs: link pairs (sorted names) never checked for collision, with the reason
            (:data:`COLLISION_REASONS`; robot.toml's ``[collision] disabled``), besides those that touch by
            construction (:func:`dualarm.sim.world.disable_unchecked_pairs`).
    """

    name: str
    directory: Path | None
    urdf: UrdfModel
    chains: Mapping[str, Chain]
    limits: Mapping[str, JointLimits]
    homes: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    description: str = ""
    disabled_pairs: Mapping[tuple[str, str], str] = field(default_factory=dict)
    assumed_limits: frozenset[str] = frozenset()

    def assumed(self, kind: str) -> str:
        """What a message about a ``kind`` limit adds: that the limit was assumed, or ""."""
        if kind not in self.assumed_limits:
            return ""
        where = f"{self.directory / 'robot.toml'} " if self.directory else ""
        return f" (an assumed {kind} limit: robot init's default, not the robot's data; replace it in {where}[limits])"

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Every movable joint of the URDF, in file order."""
        return tuple(j.name for j in self.urdf.joints if j.movable)

    def chain(self, name: str) -> Chain:
        """The chain called ``name``; RobotModelError listing the valid names otherwise."""
        if name not in self.chains:
            raise RobotModelError(
                f"robot '{excerpt(self.name, 40)}' has no chain '{excerpt(name, 40)}' (chains: {listing(self.chains)})"
            )
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
        raise RobotModelError(
            f"robot '{excerpt(self.name, 40)}' has no hand '{excerpt(hand, 40)}' (hands: {listing(hands)})"
        )

    @property
    def hands(self) -> tuple[str, ...]:
        """Names of the hands, in chain order."""
        return tuple(c.hand for c in self.chains.values() if c.hand)

    def home(self, name: str) -> Mapping[str, float]:
        """Home pose ``name`` as joint -> value [rad]."""
        if name not in self.homes:
            raise RobotModelError(
                f"robot '{excerpt(self.name, 40)}' has no home pose '{excerpt(name, 40)}' "
                f"(homes: {listing(self.homes)})"
            )
        return self.homes[name]

    def lower_upper(self, joint_names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Position limits of ``joint_names`` as two arrays [rad]."""
        return (
            np.array([self.limits[n].lower for n in joint_names]),
            np.array([self.limits[n].upper for n in joint_names]),
        )

    def limit_array(self, kind: str, joint_names: tuple[str, ...]) -> np.ndarray:
        """The ``kind`` limits of ``joint_names``, (n,).

        Kinds: ``velocity`` [rad/s], ``acceleration`` [rad/s^2], ``jerk`` [rad/s^3], ``effort`` [N m].
        """
        return np.array([getattr(self.limits[n], kind) for n in joint_names], dtype=float)

    def with_limits(self, **overrides: float | Mapping[str, float] | None) -> Robot:
        """The same robot with some limits replaced.

        ``kind=value`` for every joint, or ``kind={joint: value}`` for some (kinds ``velocity``, ``acceleration``,
        ``jerk``; None keeps the robot's).

        A task's ``[limits]`` table is applied so. With nothing to replace (every override None) it is
        this robot itself, so that what a process builds for it once is found again. A kind replaced is no longer
        :attr:`assumed_limits`.

        Raises:
            InvalidArgumentError: an unknown kind or joint, or a value that is not a positive finite number.
        """
        for kind in overrides:
            if kind not in ("velocity", "acceleration", "jerk"):
                raise InvalidArgumentError(kind, "not a limit that can be overridden (velocity, acceleration, jerk)")
        if all(value is None for value in overrides.values()):
            return self
        limits = dict(self.limits)
        for kind, value in overrides.items():
            if value is None:
                continue
            table = value if isinstance(value, Mapping) else dict.fromkeys(limits, value)
            for name, v in table.items():
                if name not in limits:
                    raise InvalidArgumentError(
                        f"{kind}.{excerpt(name, 40)}", f"no such joint in robot '{excerpt(self.name, 40)}'"
                    )
                v = _number(v, f"{kind}.{name}")
                if v <= 0:
                    raise InvalidArgumentError(f"{kind}.{name}", f"must be positive, got {v:g}")
                limits[name] = replace(limits[name], **{kind: v})
        given = {kind for kind, value in overrides.items() if value is not None}
        return replace(self, limits=MappingProxyType(limits), assumed_limits=self.assumed_limits - given)

    def configuration(self, q: Mapping[str, float] | str | None = None, name: str = "q") -> Mapping[str, float]:
        """Every movable joint's value [rad].

        ``q`` is a home pose's name, or a mapping joint -> value (joints not named at 0), or None (all at 0).

        Raises:
            InvalidArgumentError: an unknown home or joint, a value that is not finite or is
                outside the joint's position limits.
        """
        if q is None:
            return MappingProxyType(dict.fromkeys(self.joint_names, 0.0))
        if isinstance(q, str):
            if q not in self.homes:
                raise InvalidArgumentError(
                    name,
                    f"robot '{excerpt(self.name, 40)}' has no home pose '{excerpt(q, 40)}' "
                    f"(homes: {listing(self.homes)})",
                )
            return self.homes[q]
        if not isinstance(q, Mapping):
            raise InvalidArgumentError(
                name, f"expected a home pose's name or a mapping joint name -> value, got {type(q).__name__}"
            )
        values = dict.fromkeys(self.joint_names, 0.0)
        for joint, value in q.items():
            if joint not in self.limits:
                raise InvalidArgumentError(
                    f"{name}.{excerpt(joint, 40)}", f"no such joint in robot '{excerpt(self.name, 40)}'"
                )
            value = _number(value, f"{name}.{joint}")
            lim = self.limits[joint]
            if not lim.lower <= value <= lim.upper:
                raise InvalidArgumentError(
                    f"{name}.{joint}", f"{value:g} rad outside the joint limits [{lim.lower:.4f}, {lim.upper:.4f}]"
                )
            values[joint] = value
        return MappingProxyType(values)


def _number(value: Any, name: str) -> float:
    """``value`` as a finite float; InvalidArgumentError naming ``name`` otherwise."""
    number = _finite_float(value.item() if isinstance(value, (np.floating, np.integer)) else value)
    if number is None:
        raise InvalidArgumentError(name, f"expected a finite number, got {excerpt(repr(value))}")
    return number


def _limits_from_urdf(
    urdf: UrdfModel,
    acceleration: Mapping[str, float],
    jerk: Mapping[str, float],
    velocity: Mapping[str, float] | None = None,
) -> dict[str, JointLimits]:
    """Every movable joint's limits.

    Position and effort from the URDF, velocity from ``velocity`` or else the URDF, acceleration and jerk from the
    maps (inf where absent).
    """
    velocity = velocity or {}
    return {
        j.name: JointLimits(
            lower=j.lower,
            upper=j.upper,
            velocity=float(velocity.get(j.name, j.velocity)),
            acceleration=float(acceleration.get(j.name, np.inf)),
            jerk=float(jerk.get(j.name, np.inf)),
            effort=j.effort,
        )
        for j in urdf.joints
        if j.movable
    }


def robot_from_urdf(urdf_path: str | Path, base: str, tip: str) -> Robot:
    """A robot made of one chain of a bare URDF (no robot.toml): ``robot check --urdf``, ``ik srs --urdf``.

    Raises:
        RobotModelError: one line naming the file and the cause when ``urdf_path`` cannot be read
            (missing, a directory, a FIFO, ...) or is no valid URDF, or a link is not in it.
    """
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


_TOP_KEYS = {"name", "urdf", "description", "chains", "limits", "home", "collision"}
_CHAIN_KEYS = {"base", "tip", "hand"}


def _table(data: object, where: str) -> dict:
    if not isinstance(data, dict):
        raise RobotModelError(f"{where}: expected a table")
    return data


def _string(value: object, at: str) -> str:
    """``value`` if it is a non-empty string; RobotModelError naming the key ``at`` otherwise."""
    if not isinstance(value, str) or not value:
        raise RobotModelError(f"{at}: expected a non-empty string, got {excerpt(repr(value))}")
    return value


def _unknown(data: dict, allowed: set[str], where: str) -> None:
    extra = sorted(set(data) - allowed)
    if extra:
        raise RobotModelError(
            f"{where}{'' if where.endswith(':') else '.'}{excerpt(extra[0], 40)}: unknown key "
            f"(allowed: {', '.join(sorted(allowed))})"
        )


def _joint_values(data: object, where: str, joints: tuple[str, ...]) -> dict[str, float]:
    values = {}
    for name, value in _table(data, where).items():
        if name not in joints:
            raise RobotModelError(f"{where}.{excerpt(name, 40)}: no such joint (joints: {listing(joints)})")
        number = _finite_float(value)
        if number is None:
            raise RobotModelError(f"{where}.{name}: expected a finite number, got {excerpt(repr(value))}")
        values[name] = number
    return values


def _finite_float(value: object) -> float | None:
    """``value`` as a float if it is a finite number, else None.

    A TOML integer too large for a float is not.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if np.isfinite(number) else None


def _robot_toml(directory: Path) -> tuple[Path, dict]:
    """``directory/robot.toml`` parsed; RobotModelError naming it and the cause otherwise."""
    toml_path = directory / "robot.toml"
    try:
        os.stat(toml_path)
    except FileNotFoundError:
        raise RobotModelError(
            f"{excerpt(directory)}: no robot.toml (a robot directory holds robot.toml and its URDF)"
        ) from None
    except (OSError, ValueError):
        pass  # read_text names the cause
    text = read_text(toml_path, "robot description", RobotModelError)
    try:
        return toml_path, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RobotModelError(f"{excerpt(toml_path)}: not valid TOML: {exc}") from None
    except RecursionError:
        raise RobotModelError(f"{excerpt(toml_path)}: not valid TOML: tables or arrays nested too deeply") from None


def load_robot(directory: str | Path) -> Robot:
    """Load ``directory/robot.toml`` and the URDF it names.

    A bare name that is no directory here (``humanoid``) is a shipped robot (see :mod:`dualarm.data`).

    robot.toml's keys: ``name``, ``urdf`` (a file name relative to the directory), ``description``,
    ``[chains.<name>]`` (``base``, ``tip`` links, optional ``hand``), ``[limits.velocity]`` (replacing
    the URDF's), ``[limits.acceleration]`` and ``[limits.jerk]`` (joint -> value, each within
    :data:`LIMIT_RANGES`), ``[home.<name>]`` (joint -> value within the joint's position limits [rad]).
    robots/README.md documents every key.

    Raises:
        RobotModelError: one line naming ``robot.toml:key`` for anything missing or malformed, or the
            file and the cause when robot.toml or the URDF cannot be read (see :func:`dualarm.files.read_text`).
    """
    from dualarm.data import find_robot

    directory = find_robot(directory)
    toml_path, data = _robot_toml(directory)
    where = excerpt(toml_path)
    _unknown(data, _TOP_KEYS, f"{where}:")
    for key in ("name", "urdf", "chains"):
        if key not in data:
            raise RobotModelError(f"{where}:{key}: missing")
    name = _string(data["name"], f"{where}:name")
    urdf = load_urdf(directory / _string(data["urdf"], f"{where}:urdf"))
    movable = tuple(j.name for j in urdf.joints if j.movable)

    chains: dict[str, Chain] = {}
    for chain, spec in _table(data["chains"], f"{where}:chains").items():
        at = f"{where}:chains.{excerpt(chain, 40)}"
        spec = _table(spec, at)
        _unknown(spec, _CHAIN_KEYS, at)
        for key in ("base", "tip"):
            if key not in spec:
                raise RobotModelError(f"{at}.{key}: missing")
        base, tip = _string(spec["base"], f"{at}.base"), _string(spec["tip"], f"{at}.tip")
        chains[chain] = Chain(
            name=chain,
            base=base,
            tip=tip,
            joints=urdf.chain(base, tip),
            hand=_string(spec["hand"], f"{at}.hand") if "hand" in spec else None,
        )

    limits_data = _table(data.get("limits", {}), f"{where}:limits")
    _unknown(limits_data, {*LIMIT_RANGES, "assumed"}, f"{where}:limits")
    assumed = limits_data.get("assumed", [])
    if not (isinstance(assumed, list) and all(kind in LIMIT_RANGES for kind in assumed)):
        raise RobotModelError(
            f"{where}:limits.assumed: expected a list of limit kinds ({', '.join(LIMIT_RANGES)}), "
            f"got {excerpt(repr(assumed))}"
        )
    given = {kind: _joint_values(limits_data.get(kind, {}), f"{where}:limits.{kind}", movable) for kind in LIMIT_RANGES}
    for kind, values in given.items():
        low, high = LIMIT_RANGES[kind]
        for joint, value in values.items():
            if not low <= value <= high:
                raise RobotModelError(
                    f"{where}:limits.{kind}.{joint}: {value:g} is outside the allowed range [{low:g}, {high:g}]"
                )
    limits = _limits_from_urdf(urdf, given["acceleration"], given["jerk"], given["velocity"])

    homes: dict[str, Mapping[str, float]] = {}
    for home, values in _table(data.get("home", {}), f"{where}:home").items():
        at = f"{where}:home.{excerpt(home, 40)}"
        pose = _joint_values(values, at, movable)
        for joint, value in pose.items():
            lim = limits[joint]
            if not lim.lower <= value <= lim.upper:
                raise RobotModelError(
                    f"{at}.{joint}: {value:g} outside the joint limits [{lim.lower:g}, {lim.upper:g}]"
                )
        homes[home] = MappingProxyType({n: pose.get(n, 0.0) for n in movable})

    return Robot(
        name=name,
        directory=directory,
        urdf=urdf,
        chains=MappingProxyType(chains),
        limits=MappingProxyType(limits),
        homes=MappingProxyType(homes),
        description=str(data.get("description", "")).strip(),
        disabled_pairs=MappingProxyType(_disabled_pairs(data.get("collision", {}), f"{where}:collision", urdf)),
        assumed_limits=frozenset(assumed),
    )


def _disabled_pairs(data: object, where: str, urdf: UrdfModel) -> dict[tuple[str, str], str]:
    """robot.toml's ``[collision] disabled``: ``[[link, link, reason], ...]`` as sorted pair -> reason."""
    table = _table(data, where)
    _unknown(table, {"disabled"}, where)
    entries = table.get("disabled", [])
    if not isinstance(entries, list):
        raise RobotModelError(f"{where}.disabled: expected an array of [link, link, reason]")
    pairs = {}
    for k, entry in enumerate(entries):
        at = f"{where}.disabled[{k}]"
        if not (isinstance(entry, list) and len(entry) == 3 and all(isinstance(x, str) for x in entry)):
            raise RobotModelError(f"{at}: expected [link, link, reason], got {excerpt(repr(entry))}")
        a, b, reason = entry
        for link in (a, b):
            if link not in urdf.links:
                raise RobotModelError(f"{at}: no link '{excerpt(link, 40)}' in the URDF")
        if a == b:
            raise RobotModelError(f"{at}: a link paired with itself ('{excerpt(a, 40)}')")
        if reason not in COLLISION_REASONS:
            raise RobotModelError(
                f"{at}: reason {excerpt(repr(reason), 40)} is not one of {', '.join(COLLISION_REASONS)}"
            )
        first, second = sorted((a, b))
        pairs[(first, second)] = reason
    return pairs


def random_configurations(robot: Robot, chain: Chain, n: int, seed: int) -> np.ndarray:
    """``n`` configurations of ``chain`` drawn uniformly within its limits; (n, dof).

    +-pi where unlimited.
    """
    lower, upper = robot.lower_upper(chain.joint_names)
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    return np.random.default_rng(seed).uniform(lower, upper, size=(n, chain.dof))
