"""``robot.toml`` written from a layout.

Chains, limits (assumed ones marked), home poses and collision pairs.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

from dualarm.describe.layout import _Layout, lock_value
from dualarm.errors import excerpt
from dualarm.model.urdf import UrdfModel

#: Velocity written for a chain joint whose URDF gives none [rad/s] (marked ``# assumed``).
DEFAULT_VELOCITY_RAD_S = 1.0
#: Acceleration written for a chain joint when none is given: this times its velocity limit [1/s] (``# assumed``; full
#: speed in 0.4 s; the humanoid's are 2 to 4 times its velocity limits of 2-3 rad/s).
ACCELERATION_PER_S = 2.5
#: Jerk written for a chain joint when none is given: this times its acceleration limit [1/s] (``# assumed``; full
#: acceleration in 0.1 s; the humanoid's are 10 to 12.5 times its accelerations).
JERK_PER_S = 10.0
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(name: str) -> str:
    return name if _BARE.match(name) else _string(name)


def _string(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    import json

    return json.dumps(text, ensure_ascii=False)


def _number(value: float) -> str:
    return repr(float(value))


def robot_toml(
    name: str,
    urdf_file: str,
    source: Path,
    layout: _Layout,
    urdf: UrdfModel,
    srs: Mapping[str, str | None],
    limits: Mapping[str, Mapping[str, tuple[float, bool]]],
    homes: Mapping[str, Mapping[str, float]],
    touching: frozenset[tuple[str, str]],
    disabled: Mapping[tuple[str, str], str],
) -> str:
    """The text of robot.toml.

    ``limits`` is kind -> joint -> (value, assumed), ``homes`` name -> joint -> value [rad], ``disabled`` the
    ``[collision] disabled`` pairs with their reasons.
    """
    lines = [
        (
            f"# {name}: written by `dualarm robot init` from {excerpt(source.name, 60)}; "
            "robots/README.md documents every key."
        ),
        (
            "# Units: rad, rad/s, rad/s^2, rad/s^3. "
            f"The robot base frame is the URDF's root link '{urdf.root}' (x forward, y left, z up)."
        ),
        (
            "# Position and velocity limits live in the URDF (<limit>) unless [limits.velocity] replaces them; "
            "acceleration and jerk live here."
        ),
        "",
        f"name = {_string(name)}",
        f"urdf = {_string(urdf_file)}",
        (
            f'description = """\nMade by dualarm robot init from {excerpt(source.name, 60)} '
            f'({len([j for j in urdf.joints if j.movable])} movable joints)."""'
        ),
        "",
        "# A chain is the joints from `base` down to `tip`. `hand` names the hand a task drives with it.",
    ]
    for hand, base, tip in layout.arms:
        verdict = "S-R-S" if srs[hand] is None else f"not S-R-S: {srs[hand]}"
        lines += [
            f"[chains.{hand}_arm]  # {verdict}",
            f"base = {_string(base)}",
            f"tip = {_string(tip)}",
            f"hand = {_string(hand)}",
            "",
        ]
    if layout.waist:
        lines += [
            f"[chains.waist]  # the joints between the root link and the torso '{layout.torso}'",
            f"base = {_string(layout.waist[0])}",
            f"tip = {_string(layout.waist[1])}",
            "",
        ]
    if layout.locked:
        lines += [
            (
                f"# Locked: {', '.join(f'{j.name} = {lock_value(j):g}' for j in layout.locked)} "
                "(between the torso and an arm's base, in no chain; every home pose holds them)"
            ),
            "",
        ]
    assumed_kinds = [k for k in ("velocity", "acceleration", "jerk") if any(a for _, a in limits.get(k, {}).values())]
    if assumed_kinds:
        lines += [
            "[limits]  # the kinds holding values marked '# assumed': delete a kind here when you replace its values",
            f"assumed = [{', '.join(_string(k) for k in assumed_kinds)}]",
            "",
        ]
    for kind_, unit in (("velocity", "rad/s"), ("acceleration", "rad/s^2"), ("jerk", "rad/s^3")):
        table = limits.get(kind_, {})
        if not table:
            continue
        assumed = any(a for _, a in table.values())
        lines.append(
            f"[limits.{kind_}]  # [{unit}]"
            + ("; '# assumed': a default of dualarm robot init, not the robot's data: replace it" if assumed else "")
        )
        lines += [
            f"{_key(joint)} = {_number(value)}" + ("  # assumed" if a else "") for joint, (value, a) in table.items()
        ]
        lines.append("")
    lines.append("# Home poses: joint values in rad; joints not named are 0.")
    for home, values in homes.items():
        comment = (
            "  # inside the limits, clear of self-collision in PyBullet, hands in front" if home == "ready" else ""
        )
        lines.append(f"[home.{home}]{comment}")
        lines += [f"{_key(joint)} = {_number(value)}" for joint, value in values.items()]
        lines.append("")
    lines += [
        "# Link pairs not checked for collision: [link, link, reason]. Reasons: 'rigid' (joined only through",
        "# fixed joints and joints in no chain, which every motion holds), 'always' (in contact at every",
        "# configuration robot init sampled), 'user' (robot init --allow, or written here). Delete a line to",
        "# check that pair; add one to stop checking a pair.",
        "[collision]",
        "disabled = [",
        *(f"  [{_string(a)}, {_string(b)}, {_string(reason)}]," for (a, b), reason in disabled.items()),
        "]",
        "",
    ]
    if touching:
        lines.append(
            "# Link pairs dualarm never checks for collision, listed or not "
            "(touching by construction, see dualarm.sim.world.disable_unchecked_pairs):"
        )
        lines += [f"#   {a} - {b}" for a, b in sorted(touching)]
    return "\n".join(lines).rstrip() + "\n"
