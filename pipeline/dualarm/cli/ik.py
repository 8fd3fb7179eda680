"""``dualarm ik srs`` and ``dualarm ik sew``: inverse kinematics of single poses."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from dualarm.cli.app import ik_app, out, user_errors
from dualarm.cli.options import (
    MAX_ANGLE_RAD,
    MAX_POSITION_M,
    BaseLinkOption,
    TipLinkOption,
    UrdfOption,
    _robot,
    _within,
)
from dualarm.errors import DualarmError, NotSRSError, excerpt

#: What every ``dualarm ik`` command takes to name an arm and a hand pose.
PoseOption = Annotated[
    tuple[float, float, float, float, float, float],
    typer.Option(
        help="Hand pose: X Y Z [m] ROLL PITCH YAW [rad] (extrinsic x-y-z, as in task files), in the frame of --frame."
    ),
]
ArmRobotArgument = Annotated[Path | None, typer.Argument(help="Robot directory holding robot.toml (with --arm).")]
ArmOption = Annotated[str | None, typer.Option(help="Which arm of ROBOT_DIR: left or right.")]
FrameOption = Annotated[
    str,
    typer.Option(
        help="Frame of --pose: robot (the URDF's root link, waist at 0; as task files) or chain (the arm chain's base)."
    ),
]


def _arm_chain(robot_dir: Path | None, arm: str | None, urdf: Path | None, base: str | None, tip: str | None):
    """(robot, arm chain) of ``ROBOT_DIR --arm SIDE`` or of ``--urdf PATH --base LINK --tip LINK``."""
    robot = _robot(robot_dir, urdf, base, tip)
    if urdf is not None:
        return robot, robot.chain("chain")
    if arm not in ("left", "right"):
        raise DualarmError("give --arm left or --arm right with ROBOT_DIR")
    return robot, robot.hand_chain(arm)


def _pose(pose: tuple[float, ...], frame: str) -> None:
    """Refuse a --pose value outside the ranges task files allow, and a --frame other than robot or chain."""
    for name, value, bound in zip(
        ("X", "Y", "Z", "ROLL", "PITCH", "YAW"), pose, (MAX_POSITION_M,) * 3 + (MAX_ANGLE_RAD,) * 3, strict=True
    ):
        _within(value, f"--pose {name}", -bound, bound)
    if frame not in ("robot", "chain"):
        raise DualarmError(f"--frame '{excerpt(frame)}': give robot or chain")


@ik_app.command("srs")
@user_errors
def ik_srs(
    pose: PoseOption,
    arm_angle: Annotated[
        float | None, typer.Option(help="Arm angle psi of MC-Inverse eq (1) [rad] (not with --sweep).")
    ] = None,
    robot_dir: ArmRobotArgument = None,
    arm: ArmOption = None,
    urdf: UrdfOption = None,
    base: BaseLinkOption = None,
    tip: TipLinkOption = None,
    vertical: Annotated[
        tuple[float, float, float],
        typer.Option(help="Vertical vector V of the arm angle's reference plane, in the chain base frame."),
    ] = (0.0, 0.0, 1.0),
    frame: FrameOption = "robot",
    sweep: Annotated[
        bool,
        typer.Option(
            "--sweep",
            help=(
                "Instead of one arm angle: the feasible psi intervals "
                "(within the joint limits) of each of the 8 branches."
            ),
        ),
    ] = False,
    step: Annotated[float, typer.Option(help="Grid step of --sweep [deg], in [0.01, 30].")] = 1.0,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help=(
                "Print JSON: {chain, frame, pose, arm_angle, candidates}; "
                "with --sweep {chain, frame, pose, step_rad, branches}."
            ),
        ),
    ] = False,
) -> None:
    """The 8 MC-Inverse candidates of one hand pose at one arm angle (the analogue of the paper's Table I).

    With validity and the error of each candidate's forward kinematics; with --sweep, the arm angles
    at which each branch reaches the pose within the joint limits.
    """
    import json

    from dualarm.ik.analytic.mc_inverse import PoseFrame, candidate_table

    _pose(pose, frame)
    if sweep:
        if arm_angle is not None:
            raise DualarmError("give either --arm-angle PSI or --sweep")
        _within(step, "--step", 0.01, 30.0)
    elif arm_angle is None:
        raise DualarmError("give --arm-angle PSI (or --sweep for every arm angle)")
    else:
        _within(arm_angle, "--arm-angle", -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
    for value in vertical:
        _within(value, "--vertical", -MAX_POSITION_M, MAX_POSITION_M)
    robot, chain = _arm_chain(robot_dir, arm, urdf, base, tip)
    if not np.linalg.norm(vertical) > 0:
        raise DualarmError("--vertical must not be zero")
    where = PoseFrame.robot_base(robot, chain) if frame == "robot" else PoseFrame.chain_base(chain)
    if sweep:
        _ik_srs_sweep(chain, pose, vertical, where, math.radians(step), as_json)
        return
    assert arm_angle is not None
    data = candidate_table(chain, pose, arm_angle, vertical, where)
    candidates = data["candidates"]
    if as_json:
        typer.echo(json.dumps(data, indent=2))
        return
    _print_candidates(
        f"MC-Inverse, {chain.base} -> {chain.tip}, pose in the {frame} frame ({where.link}), psi = {arm_angle:g} rad",
        candidates,
        "arm_angle_rad",
    )
    out.print(f"joints: {', '.join(chain.joint_names)}; {sum(c['valid'] for c in candidates)} of 8 valid", markup=False)


@ik_app.command("sew")
@user_errors
def ik_sew(
    pose: PoseOption,
    sew_angle: Annotated[
        float,
        typer.Option(
            help="SEW angle psi [rad]: the elbow's turn about the shoulder-wrist line from the reference half-plane."
        ),
    ],
    robot_dir: ArmRobotArgument = None,
    arm: ArmOption = None,
    urdf: UrdfOption = None,
    base: BaseLinkOption = None,
    tip: TipLinkOption = None,
    reference: Annotated[
        tuple[float, float, float], typer.Option(help="Reference direction e_r of psi = 0, in the chain base frame.")
    ] = (0.0, 0.0, 1.0),
    singular: Annotated[
        tuple[float, float, float],
        typer.Option(
            help=(
                "Stereographic SEW angle: the direction e_t of its singular half-line "
                "from the shoulder, in the chain base frame (keep it out of reach)."
            )
        ),
    ] = (0.0, 0.0, -1.0),
    conventional: Annotated[
        bool,
        typer.Option(
            "--conventional",
            help="The conventional SEW angle (singular along the whole line through the shoulder along e_r) instead.",
        ),
    ] = False,
    frame: FrameOption = "robot",
    as_json: Annotated[
        bool,
        typer.Option("--json", help="Print JSON: {chain, frame, pose, sew_angle, reference, singular, candidates}."),
    ] = False,
) -> None:
    """Every solution of one hand pose at one SEW angle for a 7R arm of a SEW family (Elias and Wen).

    A SEW family: joints 2-3 and 5-7 meet (an offset humanoid shoulder, any S-R-S arm), or joints
    1-3 and 5-6 (the Panda). With validity and the error of each solution's forward kinematics (the
    analogue of ik srs).

    Exits 2 with one line for an arm of another family, or when no solution exists at that SEW angle
    (the pose out of reach, or the elbow unable to lie in that half-plane).
    """
    import json

    from dualarm.errors import UnreachablePoseError
    from dualarm.ik.analytic.mc_inverse import PoseFrame
    from dualarm.ik.analytic.sew import SewAngle, candidate_table

    _pose(pose, frame)
    _within(sew_angle, "--sew-angle", -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
    directions = {"--reference": np.asarray(reference, dtype=float), "--singular": np.asarray(singular, dtype=float)}
    for option, direction in directions.items():
        if not (np.all(np.isfinite(direction)) and np.linalg.norm(direction) > 0):
            raise DualarmError(f"{option} must be a finite non-zero direction")
    e_r, e_t = (v / np.linalg.norm(v) for v in directions.values())
    if not conventional and np.linalg.norm(np.cross(e_r, e_t)) < 1e-9 and e_r @ e_t > 0:
        raise DualarmError("--singular must not point along --reference (the stereographic angle needs e_t != e_r)")
    robot, chain = _arm_chain(robot_dir, arm, urdf, base, tip)
    where = PoseFrame.robot_base(robot, chain) if frame == "robot" else PoseFrame.chain_base(chain)
    sew = SewAngle(
        reference=(float(e_r[0]), float(e_r[1]), float(e_r[2])),
        singular=None if conventional else (float(e_t[0]), float(e_t[1]), float(e_t[2])),
    )
    candidates = candidate_table(robot, chain, where.to_chain(pose), sew_angle, sew)
    if not candidates:
        raise UnreachablePoseError(
            f"no solution at psi = {sew_angle:g} rad: the pose is out of reach, "
            "or this SEW angle puts the elbow where the arm cannot reach it"
        )
    if as_json:
        data = {
            "chain": {"base": chain.base, "tip": chain.tip, "joints": list(chain.joint_names)},
            "frame": where.record(),
            "pose": list(pose),
            "sew_angle": sew_angle,
            "reference": list(sew.reference),
            "singular": list(sew.singular) if sew.singular is not None else None,
            "candidates": candidates,
        }
        typer.echo(json.dumps(data, indent=2))
        return
    kind = "conventional" if conventional else "stereographic"
    _print_candidates(
        f"SEW IK, {chain.base} -> {chain.tip}, pose in the {frame} "
        f"frame ({where.link}), {kind} psi = {sew_angle:g} rad",
        candidates,
        "sew_angle_rad",
    )
    out.print(
        f"joints: {', '.join(chain.joint_names)}; {len(candidates)} solutions, "
        f"{sum(c['valid'] for c in candidates)} within the joint limits",
        markup=False,
    )


def _sew_line(chain) -> str:
    """``robot check``'s line on a 7-DOF chain's SEW family, or why it has none.

    The family is what ``--ik sew`` and ``ik sew`` need.
    """
    from dualarm.model.sew import FIRST_JOINT_FAMILY, sew_chain

    try:
        arm = sew_chain(chain)
    except NotSRSError as exc:
        return f"no SEW family: {exc}"
    first = arm.family == FIRST_JOINT_FAMILY
    offset = float(np.linalg.norm(arm.crossing - arm.shoulder if first else arm.wrist - arm.crossing))
    where = "shoulder (joints 2-3 from axis 1)" if first else "wrist (axis 7 from joints 5-6)"
    return (
        f"SEW family {arm.family} (--ik sew, ik sew): S = "
        f"{(np.round(arm.shoulder, 4) + 0.0).tolist()} m, {where} offset {offset:.4f} m"
    )


def _print_candidates(title: str, candidates: list[dict], angle: str) -> None:
    """``ik srs``'s and ``ik sew``'s table.

    Each candidate's joints, validity (the reason's head), FK errors and its angle (the key
    ``angle``).
    """
    table = Table(title=title, title_justify="left")
    for column in ("#", *[f"θ{i}" for i in range(1, 8)], "validity", "pos. err [m]", "rot. err [rad]", "ψ of q [rad]"):
        table.add_column(column, justify="left" if column == "validity" else "right", no_wrap=True)
    for i, c in enumerate(candidates):
        table.add_row(
            str(i + 1),
            *(f"{v:.4f}" for v in c["q"]),
            c["reason"].split(" at ")[0],
            f"{c['position_error_m']:.1e}",
            f"{c['orientation_error_rad']:.1e}",
            f"{c[angle]:.4f}",
        )
    out.print(table)


def _ik_srs_sweep(
    chain, pose: tuple[float, ...], vertical: tuple[float, float, float], frame, step_rad: float, as_json: bool
) -> None:
    """``ik srs --sweep``: each branch's feasible arm-angle intervals at ``pose`` (in ``frame``).

    As a table or JSON.
    """
    import json

    from dualarm.ik.analytic.mc_inverse import McInverse, branch_label, sweep_arm_angle, sweep_table

    length = float(np.linalg.norm(vertical))
    result = sweep_arm_angle(
        McInverse.of(chain, (vertical[0] / length, vertical[1] / length, vertical[2] / length)),
        frame.to_chain(pose),
        step_rad,
    )
    rows = sweep_table(result)
    if as_json:
        data = {
            "chain": {"base": chain.base, "tip": chain.tip, "joints": list(chain.joint_names)},
            "frame": frame.record(),
            "pose": list(pose),
            "step_rad": step_rad,
            "branches": rows,
        }
        typer.echo(json.dumps(data, indent=2))
        return
    table = Table(
        title=(
            f"MC-Inverse arm-angle sweep, {chain.base} -> {chain.tip}, pose in the "
            f"{frame.kind} frame ({frame.link}), step {math.degrees(step_rad):g} deg"
        ),
        title_justify="left",
    )
    for column in ("branch", "feasible psi [rad]", "samples"):
        table.add_column(column, justify="right" if column == "samples" else "left", no_wrap=column == "branch")
    for b, row in enumerate(rows):
        spans = (
            ", ".join(
                f"[{lo:.4f}, {hi:.4f}]" if hi <= math.pi else f"[{lo:.4f}, {hi - 2 * math.pi:.4f}] across ±pi"
                for lo, hi in row["intervals_rad"]
            )
            or f"none ({row['blocked_by']})"
        )
        table.add_row(branch_label(b), spans, str(row["valid_samples"]))
    out.print(table)
    feasible = sum(bool(r["intervals_rad"]) for r in rows)
    out.print(
        f"{feasible} of 8 branches reach the pose within the joint limits; interval "
        "ends are grid samples (the true ends lie within one step outside)",
        markup=False,
    )
