"""The collision matrix ``robot init`` writes: the link pairs not checked, each with its reason.

As MoveIt Setup Assistant's, from the URDF and sampled configurations:

- ``adjacent``: a link and its nearest ancestor with geometry, when they touch by construction. dualarm
  skips these itself (:func:`dualarm.sim.world.disable_unchecked_pairs`); robot.toml lists them as a comment.
- ``rigid``: two links joined only through fixed joints and joints in no chain (every motion holds those),
  which never move relative to each other in a task (a TALOS wrist's force sensor and its hand; Romeo's head,
  held, on its torso, which PyBullet's motors let sag 0.015 mm into it).
- ``always``: in contact at every one of :data:`~dualarm.describe.ready.SAMPLES` random configurations of
  the chains' joints (a forearm shell that overlaps the wrist at any angle): checking them would only
  report them.
- ``user``: named by ``robot init --allow`` (or written into robot.toml by hand).

Pairs never in contact are still checked (MoveIt's "never" pairs are a speed-up, not a fact).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from itertools import combinations

from dualarm.describe.ready import SAMPLES, SEED, _samples, contact_pairs
from dualarm.errors import RobotModelError, excerpt
from dualarm.files import listing
from dualarm.model.robot import Robot
from dualarm.model.urdf import UrdfModel


def rigid_pairs(urdf: UrdfModel, solid: Iterable[str], moving: Iterable[str] = ()) -> set[tuple[str, str]]:
    """Pairs of links of ``solid`` (those with geometry) joined through no joint of ``moving`` (sorted)."""
    group = {link: link for link in urdf.links}

    def find(link: str) -> str:
        while group[link] != link:
            group[link] = group[group[link]]
            link = group[link]
        return link

    moving = set(moving)
    for j in urdf.joints:
        if j.name not in moving:
            group[find(j.child)] = find(j.parent)
    members: dict[str, list[str]] = {}
    for link in sorted(solid):
        members.setdefault(find(link), []).append(link)
    return {(a, b) for links in members.values() for a, b in combinations(links, 2)}


def always_in_contact(
    robot: Robot, sim, base: Mapping[str, float], samples: int = SAMPLES, seed: int = SEED
) -> set[tuple[str, str]]:
    """Link pairs PyBullet finds penetrating at every one of ``samples`` random configurations.

    Configurations of the chains' joints (the others at ``base``), of the pairs ``sim`` checks.
    """
    joints = sorted({n for c in robot.chains.values() for n in c.joint_names})
    always: set[tuple[str, str]] | None = None
    for q in _samples(robot, joints, samples, seed):
        pairs = contact_pairs(sim, {**base, **dict(zip(joints, q, strict=True))})
        always = pairs if always is None else always & pairs
        if not always:
            break
    return always or set()


def allowed_pairs(urdf: UrdfModel, allow: Iterable[tuple[str, str]]) -> set[tuple[str, str]]:
    """``robot init --allow A B`` pairs as sorted names.

    Raises:
        RobotModelError: a link the URDF does not have, or a link paired with itself.
    """
    pairs = set()
    for a, b in allow:
        for link in (a, b):
            if link not in urdf.links:
                raise RobotModelError(
                    f"--allow '{excerpt(link, 40)}': no such link in {excerpt(urdf.path)} "
                    f"(links: {listing(urdf.links)})"
                )
        if a == b:
            raise RobotModelError(f"--allow '{excerpt(a, 40)}' '{excerpt(b, 40)}': a link paired with itself")
        pairs.add((min(a, b), max(a, b)))
    return pairs


def disabled_pairs(
    robot: Robot, sim, touching: frozenset[tuple[str, str]], held: Mapping[str, float], allow: Iterable[tuple[str, str]]
) -> dict[tuple[str, str], str]:
    """The pairs robot.toml's ``[collision] disabled`` lists, with their reasons; turned off in ``sim``.

    ``touching``: the pairs ``sim`` already skips (not listed again).
    """
    import xml.etree.ElementTree as ET

    from dualarm.sim.world import disable_pairs

    # from the URDF, not PyBullet: a robot of more links than PyBullet reports has its fixed links merged there
    solid = {
        link.get("name", "")
        for link in ET.parse(robot.urdf.path).getroot().iter("link")
        if link.find("collision") is not None
    }
    out = dict.fromkeys(sorted(allowed_pairs(robot.urdf, allow) - touching), "user")
    chains = {n for chain in robot.chains.values() for n in chain.joint_names}
    out |= dict.fromkeys(sorted(rigid_pairs(robot.urdf, solid, chains) - touching - set(out)), "rigid")
    disable_pairs(sim, out)
    out |= dict.fromkeys(sorted(always_in_contact(robot, sim, held)), "always")
    disable_pairs(sim, out)
    return out
