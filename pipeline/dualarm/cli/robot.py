"""``dualarm robot check``, ``init`` and ``poses``: robot descriptions."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from dualarm.cli.app import err, out, robot_app, user_errors
from dualarm.cli.ik import _sew_line
from dualarm.cli.options import MAX_SAMPLES, _out_path, _robot, _seed, _within
from dualarm.errors import InvalidArgumentError, NotSRSError, excerpt


@robot_app.command("check")
@user_errors
def robot_check(
    robot_dir: Annotated[
        Path | None, typer.Argument(help="Robot directory holding robot.toml (e.g. robots/humanoid).")
    ] = None,
    urdf: Annotated[
        Path | None, typer.Option(help="Check one chain of a bare URDF instead (needs --base and --tip).")
    ] = None,
    base: Annotated[str | None, typer.Option(help="Base link of the chain (with --urdf).")] = None,
    tip: Annotated[str | None, typer.Option(help="Tip link of the chain (with --urdf).")] = None,
    samples: Annotated[
        int, typer.Option(min=1, help=f"Random configurations per chain (at most {MAX_SAMPLES}).")
    ] = 1000,
    seed: Annotated[int, typer.Option(help="Seed of the random configurations (an integer >= 0).")] = 0,
) -> None:
    """Print chains, DOF and limits, and check the CasADi kinematics.

    Against adam-robotics, PyBullet and finite differences; exit 0 only if every figure is within
    tolerance.
    """
    from dualarm.describe.check import FK_TOLERANCE, JACOBIAN_TOLERANCE, PYBULLET_TOLERANCE, check_chain, require_limits
    from dualarm.model.srs import srs_geometry

    _seed(seed)
    _within(samples, "--samples", 1, MAX_SAMPLES)
    robot = _robot(robot_dir, urdf, base, tip)
    require_limits(robot)
    out.print(f"robot {robot.name}: {robot.urdf.path}  ({len(robot.joint_names)} movable joints)", markup=False)
    results = []
    for chain in robot.chains.values():
        out.print(
            f"\nchain {chain.name}: {chain.base} -> {chain.tip}, {chain.dof} DOF"
            + (f", hand '{chain.hand}'" if chain.hand else ""),
            markup=False,
        )
        limits = Table(show_edge=False, pad_edge=False)
        for column in ("joint", "lower [rad]", "upper [rad]", "vel [rad/s]", "acc [rad/s²]", "jerk [rad/s³]"):
            limits.add_column(column, justify="left" if column == "joint" else "right")
        for name in chain.joint_names:
            lim = robot.limits[name]
            limits.add_row(
                name, *(f"{v:.4g}" for v in (lim.lower, lim.upper, lim.velocity, lim.acceleration, lim.jerk))
            )
        out.print(limits)
        if chain.dof == 7:
            try:
                g = srs_geometry(chain)
                out.print(
                    f"S-R-S: shoulder S = {(np.round(g.shoulder, 4) + 0.0).tolist()} m, L2 = {g.upper_arm:.4f} m, "
                    f"L3 = {g.forearm:.4f} m, wrist-to-tip = {(np.round(g.tool_from_wrist, 4) + 0.0).tolist()} m",
                    markup=False,
                )
            except NotSRSError as exc:
                out.print(f"not S-R-S: {exc}", markup=False)
            out.print(_sew_line(chain), markup=False)
        with err.status(f"checking {chain.name} on {samples} configurations ..."):
            results.append(check_chain(robot, chain, samples=samples, seed=seed))
    table = Table(
        title=f"kinematics check ({samples} random configurations per chain, seed {seed})", title_justify="left"
    )
    for column in ("chain", "FK vs adam [m]", "[rad]", "FK vs PyBullet [m]", "[rad]", "Jacobian vs FD", "result"):
        table.add_column(column, justify="left" if column == "chain" else "right")
    for r in results:
        table.add_row(
            r.chain,
            f"{r.fk_position_error_m:.2e}",
            f"{r.fk_rotation_error_rad:.2e}",
            f"{r.pybullet_position_error_m:.2e}",
            f"{r.pybullet_rotation_error_rad:.2e}",
            f"{r.jacobian_error:.2e}",
            "pass" if r.passed else "FAIL",
        )
    out.print(table)
    out.print(
        f"tolerances: FK vs adam-robotics (double precision) {FK_TOLERANCE:g} m / rad; FK vs PyBullet "
        f"{PYBULLET_TOLERANCE:g} (PyBullet reports link poses in single precision); Jacobian {JACOBIAN_TOLERANCE:g}",
        markup=False,
    )
    if not all(r.passed for r in results):
        raise typer.Exit(1)


@robot_app.command("init")
@user_errors
def robot_init(
    urdf: Annotated[
        Path,
        typer.Argument(
            help=(
                "The robot's URDF (mesh paths: package:// through ROS_PACKAGE_PATH "
                "or the URDF's own folders, file://, absolute or relative)."
            )
        ),
    ],
    out_dir: Annotated[
        str,
        typer.Option(
            "--out", help="The robot directory to write (new or empty): robot.toml, a copy of the URDF and its meshes."
        ),
    ],
    left_tip: Annotated[
        str | None, typer.Option(help="Tip link (hand frame) of the left arm; default: proposed from the tree.")
    ] = None,
    right_tip: Annotated[
        str | None, typer.Option(help="Tip link of the right arm; default: proposed from the tree.")
    ] = None,
    left_base: Annotated[
        str | None, typer.Option(help="Base link of the left arm's chain; default: the torso.")
    ] = None,
    right_base: Annotated[
        str | None, typer.Option(help="Base link of the right arm's chain; default: the torso.")
    ] = None,
    torso: Annotated[
        str | None,
        typer.Option(
            help="The link the arms hang from; default: their common root. The waist is the movable joints above it."
        ),
    ] = None,
    acceleration: Annotated[
        float | None,
        typer.Option(
            help=(
                "Acceleration limit of every chain joint [rad/s^2]; default: assumed, 2.5/s times its velocity limit, "
                "marked so in robot.toml."
            )
        ),
    ] = None,
    jerk: Annotated[
        float | None,
        typer.Option(
            help=(
                "Jerk limit of every chain joint [rad/s^3]; default: assumed, 10/s times its acceleration limit, "
                "marked so in robot.toml."
            )
        ),
    ] = None,
    up: Annotated[
        str | None,
        typer.Option(
            help=(
                "The axis of the URDF's root frame that points up (x, -x, y, -y, z, -z); other than z, a new root "
                "turned z-up (y towards the left arm) holds it. Default z, refused when the arms say otherwise."
            )
        ),
    ] = None,
    allow: Annotated[
        list[str] | None,
        typer.Option(
            metavar="LINK_A,LINK_B",
            help="Two links never to check for collision against each other (repeatable); robot.toml [collision].",
        ),
    ] = None,
) -> None:
    """Write a robot directory from a URDF; print every choice (robots/README.md).

    Arm chains, waist, locked joints, S-R-S verdicts, limits, home poses zero and ready.
    """
    from dualarm.describe.init import init_robot

    for value, option in ((acceleration, "--acceleration"), (jerk, "--jerk")):
        if value is not None:
            _within(value, option, 0.0, above_low=True)
    with err.status("robot init: reading the URDF ...") as status:
        result = init_robot(
            urdf,
            _out_path(out_dir, "--out"),
            left_tip=left_tip,
            right_tip=right_tip,
            left_base=left_base,
            right_base=right_base,
            torso=torso,
            acceleration=acceleration,
            jerk=jerk,
            allow=[_link_pair(text) for text in allow or ()],
            up=up,
            progress=lambda text: status.update(f"robot init: {text} ..."),
        )
    for line in result.notes:
        out.print(line, markup=False, soft_wrap=True)
    out.print(
        f"wrote {result.directory / 'robot.toml'}; next: dualarm robot "
        f"check {result.directory}, dualarm robot poses {result.directory}",
        markup=False,
        soft_wrap=True,
    )


def _link_pair(text: str) -> tuple[str, str]:
    """``LINK_A,LINK_B`` as two names; InvalidArgumentError otherwise."""
    parts = text.split(",")
    if len(parts) != 2 or not all(parts):
        raise InvalidArgumentError("--allow", f"expected LINK_A,LINK_B, got {excerpt(repr(text))}")
    return parts[0], parts[1]


@robot_app.command("poses")
@user_errors
def robot_poses(
    robot_dir: Annotated[Path, typer.Argument(help="Robot directory holding robot.toml (or a shipped robot's name).")],
    pose: Annotated[str | None, typer.Option(help="Only this home pose (default: every one).")] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print JSON: [{home, hand, position_m, rpy_rad, arm_angle_rad}].")
    ] = False,
) -> None:
    """Each hand's pose at each home pose, and the arm angle psi [rad] where the arm is S-R-S.

    Position [m] and roll, pitch, yaw (extrinsic x-y-z, as task files) [rad] in the robot base
    frame.
    """
    import dataclasses
    import json

    from dualarm.describe.poses import home_hand_poses
    from dualarm.model.robot import load_robot

    poses = home_hand_poses(load_robot(robot_dir), pose)
    if as_json:
        typer.echo(json.dumps([dataclasses.asdict(p) for p in poses], indent=2))
        return
    table = Table(title="hand poses in the robot base frame", title_justify="left")
    for column in ("home", "hand", "x [m]", "y [m]", "z [m]", "roll [rad]", "pitch [rad]", "yaw [rad]", "ψ [rad]"):
        table.add_column(column, justify="left" if column in ("home", "hand") else "right", no_wrap=True)
    for p in poses:
        table.add_row(
            p.home,
            p.hand,
            *(f"{v:.4f}" for v in (*p.position_m, *p.rpy_rad)),
            "-" if p.arm_angle_rad is None else f"{p.arm_angle_rad:.4f}",
        )
    out.print(table)
    out.print(
        "ψ: the arm angle of MC-Inverse eq (1) (V = +z of the arm's base frame); '-' "
        "where the arm is not S-R-S or ψ is undefined (shoulder-wrist line vertical)",
        markup=False,
    )
