"""The papers' experiments as parts of ``dualarm reproduce``: what each runs and where it writes.

Each part is a function ``(out, robot, progress) -> outputs`` that runs one experiment on the
robot directory ``robot`` with the same code as the command that reproduces it alone
(:func:`command`), writes under ``out`` and returns the paths it wrote (run directories, tables),
relative to ``out``. ``progress(fraction, text)`` reports how far it is. Parts are independent,
so they can run as separate Dask tasks. On a robot other than the humanoid a part may be not
available (:func:`unavailable`): its task does not load there, or it needs what the robot lacks.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from dualarm.data import robots_dir, tasks_dir
from dualarm.errors import StageError

if TYPE_CHECKING:
    from dualarm.model.robot import Robot

#: The shipped task files (package data, see :mod:`dualarm.data`).
TASKS = tasks_dir()
#: The robot every task is written for (``--robot`` replaces it).
ROBOT = robots_dir() / "humanoid"

Progress = Callable[[float, str], None]


class Outputs(TypedDict, total=False):
    """The paths a part wrote, relative to the reproduction directory.

    Attributes:
        runs: its run directories.
        table: its table (CSV or JSON).
        summary: its JSON summary.
    """

    runs: list[str]
    table: str
    summary: str


#: The MC-Inverse paper's Table I solution 1 [rad] (HR2's left arm, joints 1-7). Its pose is
#: given in HR2's arm base frame, which this robot does not share; the analogue puts this robot's
#: arm in this configuration instead and asks for its pose back (see :func:`table_i`).
TABLE_I_SOLUTION_1 = (-1.84799, 0.21282, -2.08281, -1.94261, 0.54827, 1.29769, 1.38904)
#: Planning trials of the bowl grasp.
PLAN_TRIALS = 100
#: The MC-Inverse paper's methods for the dual-arm box (its Fig. 16).
CARRY_BOX_METHODS = ("mc-inverse", "trac-ik", "ikfast-style")


def _relative(path: Path, out: Path) -> str:
    return str(Path(path).resolve().relative_to(out.resolve()))


def robot_option(robot: Path) -> list[str]:
    """``["--robot", robot]`` for a robot other than :data:`ROBOT`, else nothing."""
    return [] if robot.resolve() == ROBOT.resolve() else ["--robot", str(robot)]


def _run(task: str, ik: str, stages: tuple[str, ...] | None, out: Path, robot: Path, progress: Progress) -> Outputs:
    from dualarm.run import record_run, resolve_stages
    from dualarm.tasks import load_task

    chosen = resolve_stages(stages, ik)
    command = [
        "dualarm",
        "run",
        f"tasks/{task}.toml",
        "--ik",
        ik,
        *(["--stages", ",".join(stages)] if stages else []),
        *robot_option(robot),
    ]
    try:
        run = record_run(
            load_task(TASKS / f"{task}.toml", robot=robot),
            ik,
            stages=chosen,
            out_dir=out / "runs",
            command=command,
            progress=lambda stage: progress(chosen.index(stage) / len(chosen) if stage in chosen else 0.95, stage),
        )
    except StageError as exc:  # the run is recorded as failed: a verdict the claims resting on it report
        if exc.run_directory is None:
            raise
        return {"runs": [_relative(exc.run_directory, out)]}
    assert run.directory is not None  # record_run always returns its run directory
    return {"runs": [_relative(run.directory, out)]}


def ball_game_tvgdd(out: Path, robot: Path, progress: Progress) -> Outputs:
    """TV-GDD on the ball game, through every stage (Zhang, Kong, Niu, section 4, Figs 5-8)."""
    return _run("ball_game", "tvgdd", None, out, robot, progress)


def ball_game_pinv(out: Path, robot: Path, progress: Progress) -> Outputs:
    """The pseudoinverse baseline on the ball game, IK only (Figs 3-4)."""
    return _run("ball_game", "pinv", ("path", "ik"), out, robot, progress)


def table_i_pose(robot: Path = ROBOT) -> tuple[list[float], float]:
    """The Table I analogue's hand pose and arm angle [rad], at the paper's solution 1 joints.

    The pose: X Y Z [m] ROLL PITCH YAW [rad], in the left arm's base frame; where ``robot``'s left
    hand is, and its arm angle, with the arm at the paper's solution 1 joints.
    """
    import numpy as np
    from scipy.spatial.transform import Rotation

    from dualarm.model.kinematics import ChainKinematics
    from dualarm.model.robot import load_robot
    from dualarm.model.srs import SrsKinematics

    chain = load_robot(robot).hand_chain("left")
    q = np.array([TABLE_I_SOLUTION_1])
    T = ChainKinematics.of(chain).poses(q)[0]
    pose = [*T[:3, 3].tolist(), *Rotation.from_matrix(T[:3, :3]).as_euler("xyz").tolist()]
    return [round(v, 6) for v in pose], round(float(SrsKinematics.of(chain).arm_angles(q)[0]), 6)


def table_i(out: Path, robot: Path, progress: Progress) -> Outputs:
    """MC-Inverse Table I: the 8 candidates of one pose at one arm angle, as ``table_i.json``.

    The JSON of ``dualarm ik srs --json``.
    """
    from dualarm.ik.analytic.mc_inverse import candidate_table
    from dualarm.model.robot import load_robot

    pose, psi = table_i_pose(robot)
    data = candidate_table(load_robot(robot).hand_chain("left"), tuple(pose), psi)
    path = out / "table_i.json"
    path.write_text(json.dumps(data, indent=2) + "\n")
    return {"table": _relative(path, out)}


def _consistency(task: str, methods: tuple[str, ...] | None, out: Path, robot: Path, progress: Progress) -> Outputs:
    from dualarm.report.consistency import DEFAULT_METHODS, run_consistency

    done: list[str] = []

    def step(text: str) -> None:
        progress(len(done) / len(methods or DEFAULT_METHODS), text)
        done.append(text)

    result = run_consistency(
        TASKS / f"{task}.toml",
        methods,
        out / "consistency" / task,
        progress=step,
        robot=None if not robot_option(robot) else robot,
    )
    return {"table": _relative(result.csv, out), "runs": [_relative(Path(r), out) for r in result.table["run"] if r]}


def triangle_consistency(out: Path, robot: Path, progress: Progress) -> Outputs:
    """Every IK method that runs on the robot drawing the triangle 5 times (MC-Inverse V.B, Figs 9-10)."""
    return _consistency("triangle", None, out, robot, progress)


def circle_consistency(out: Path, robot: Path, progress: Progress) -> Outputs:
    """Every IK method that runs on the robot drawing the circle 5 times (MC-Inverse V.C, Figs 12-13)."""
    return _consistency("circle", None, out, robot, progress)


def carry_box(out: Path, robot: Path, progress: Progress) -> Outputs:
    """The dual-arm box carried up and down 5 times.

    The paper's three methods compared over the repetitions (Fig. 16), and MC-Inverse through every
    stage (eq 11, Fig. 14).
    """
    compared = _consistency("carry_box", CARRY_BOX_METHODS, out, robot, lambda f, text: progress(0.6 * f, text))
    executed = _run("carry_box", "mc-inverse", None, out, robot, lambda f, text: progress(0.6 + 0.4 * f, text))
    return {"table": compared["table"], "runs": [*compared["runs"], *executed["runs"]]}


def bowl_grasp(out: Path, robot: Path, progress: Progress) -> Outputs:
    """MCIKRRT planning the bowl grasp :data:`PLAN_TRIALS` times (Li & Liang, section 5).

    The first plan retimed, smoothed, executed and recorded.
    """
    from dualarm.study.planning import run_trials

    result = run_trials(
        TASKS / "bowl_grasp.toml",
        "mcikrrt",
        PLAN_TRIALS,
        0,
        out / "plan" / "bowl_grasp-mcikrrt",
        recordings=out / "runs",
        command=["dualarm", "plan", "tasks/bowl_grasp.toml", "--trials", str(PLAN_TRIALS), *robot_option(robot)],
        progress=lambda done, total: progress(0.7 * done / total, f"trial {done}/{total}"),
        robot=None if not robot_option(robot) else robot,
    )
    return {
        "table": _relative(result.directory / "plan_trials.csv", out),
        "summary": _relative(result.directory / "plan_summary.json", out),
        "runs": [_relative(result.run, out)] if result.run else [],
    }


def _left_arm_at_solution_1(robot: Robot) -> str:
    """Why Table I's analogue cannot run on ``robot`` ("" when it can).

    It needs an S-R-S left arm whose limits hold the paper's solution 1.
    """
    from dualarm.methods import not_srs

    if "left" not in robot.hands:
        return f"needs a left arm; robot '{robot.name}' has {', '.join(robot.hands)}"
    if reason := not_srs(robot, ("left",)).get("left"):
        return f"needs an S-R-S left arm: {reason}"
    for name, value in zip(robot.hand_chain("left").joint_names, TABLE_I_SOLUTION_1, strict=True):
        low, high = robot.limits[name].lower, robot.limits[name].upper
        if not low <= value <= high:
            return f"the paper's solution 1 puts {name} at {value:g} rad, outside its limits [{low:g}, {high:g}]"
    return ""


def _srs_arms(robot: Robot) -> str:
    """Why the carried box's methods cannot run on ``robot`` ("" when they can).

    MC-Inverse and IKFast-style need both arms S-R-S.
    """
    from dualarm.methods import not_srs

    reasons = not_srs(robot, tuple(h for h in ("left", "right") if h in robot.hands))
    return f"its methods (MC-Inverse, IKFast-style) need S-R-S arms: {next(iter(reasons.values()))}" if reasons else ""


def _waist(robot: Robot) -> str:
    """Why the bowl grasp cannot run on ``robot`` ("" when it can): it plans with the waist free."""
    return "" if "waist" in robot.chains else f"plans with the waist free; robot '{robot.name}' has no [chains.waist]"


@dataclass(frozen=True)
class Part:
    """One experiment of the reproduction.

    Attributes:
        name: its name on the command line (``--only``).
        paper: the paper it reproduces.
        title: what it is.
        command: the command that reproduces it alone, on the humanoid (see :func:`command`).
        run: the function that runs it (see the module's docstring).
        seconds: about how long it takes alone on a 2-core machine [s]; the longest start first.
        task: the shipped task it runs (a robot it does not load on cannot run the part).
        needs: why a robot cannot run it beyond its task ("" when it can).
    """

    name: str
    paper: str
    title: str
    command: str
    run: Callable[[Path, Path, Progress], Outputs]
    seconds: float
    task: str = ""
    needs: Callable[[Robot], str] = lambda robot: ""


PARTS = (
    Part(
        "ball-game-tvgdd",
        "TV-GDD",
        "ball game, TV-GDD, every stage",
        "dualarm run tasks/ball_game.toml --ik tvgdd",
        ball_game_tvgdd,
        13,
        "ball_game",
    ),
    Part(
        "ball-game-pinv",
        "TV-GDD",
        "ball game, pseudoinverse baseline",
        "dualarm run tasks/ball_game.toml --ik pinv --stages path,ik",
        ball_game_pinv,
        4,
        "ball_game",
    ),
    Part(
        "table-i",
        "MC-Inverse",
        "Table I analogue",
        "dualarm ik srs robots/humanoid --arm left --pose {pose} --arm-angle {psi} --frame chain",
        table_i,
        1,
        needs=_left_arm_at_solution_1,
    ),
    Part(
        "triangle",
        "MC-Inverse",
        "triangle drawn 5 times, every IK method",
        "dualarm consistency tasks/triangle.toml",
        triangle_consistency,
        28,
        "triangle",
    ),
    Part(
        "circle",
        "MC-Inverse",
        "circle drawn 5 times, every IK method",
        "dualarm consistency tasks/circle.toml",
        circle_consistency,
        18,
        "circle",
    ),
    Part(
        "carry-box",
        "MC-Inverse",
        "dual-arm box carried 5 times",
        "dualarm consistency tasks/carry_box.toml --methods "
        f"{','.join(CARRY_BOX_METHODS)}; dualarm run tasks/carry_box.toml --ik mc-inverse",
        carry_box,
        15,
        "carry_box",
        _srs_arms,
    ),
    Part(
        "bowl-grasp",
        "Li & Liang",
        f"bowl grasp planned {PLAN_TRIALS} times (MCIKRRT)",
        f"dualarm plan tasks/bowl_grasp.toml --trials {PLAN_TRIALS}",
        bowl_grasp,
        18,
        "bowl_grasp",
        _waist,
    ),
)
#: Parts by name.
BY_NAME = {p.name: p for p in PARTS}


def unavailable(part: Part, robot: Path) -> str:
    """Why ``part`` cannot run on the robot directory ``robot`` ("" when it can), in one line.

    What it needs and the robot lacks, or why its task does not load there.

    Raises:
        RobotModelError: ``robot`` is not a robot directory.
    """
    from dualarm.errors import TaskFileError
    from dualarm.model.robot import load_robot
    from dualarm.tasks import load_task

    if reason := part.needs(load_robot(robot)):
        return reason
    if part.task:
        try:
            load_task(TASKS / f"{part.task}.toml", robot=robot)
        except TaskFileError as exc:
            return f"its task does not load on this robot: {exc}"
    return ""


def command(part: Part, robot: Path = ROBOT) -> str:
    """The command that reproduces ``part`` alone on the robot directory ``robot``.

    ``--robot`` added to each dualarm command unless it is the humanoid.
    """
    option = robot_option(robot)
    if not option:
        return part.command
    if part.name == "table-i":
        return part.command.replace("robots/humanoid", str(robot))
    return "; ".join(f"{c} {' '.join(option)}" for c in part.command.split("; "))
