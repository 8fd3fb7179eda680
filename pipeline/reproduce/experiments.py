"""The papers' experiments as parts of ``dualarm reproduce``: what each runs and where it writes.

Each part is a function ``(out, progress) -> outputs`` that runs one experiment with the same code
as the command that reproduces it alone (:attr:`Part.command`), writes under ``out`` and returns
the paths it wrote (run directories, tables), relative to ``out``. ``progress(fraction, text)``
reports how far it is. Parts are independent, so they can run in separate processes.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

from dualarm.data import robots_dir, tasks_dir

#: The shipped task files (package data, see :mod:`dualarm.data`).
TASKS = tasks_dir()
#: The robot every task uses.
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


def _run(task: str, ik: str, stages: tuple[str, ...] | None, out: Path, progress: Progress) -> Outputs:
    from dualarm.run import record_run, resolve_stages

    chosen = resolve_stages(stages, ik)
    command = ["dualarm", "run", f"tasks/{task}.toml", "--ik", ik, *(["--stages", ",".join(stages)] if stages else [])]
    run = record_run(
        TASKS / f"{task}.toml", ik, stages=chosen, out_dir=out / "runs", command=command, progress=lambda stage: progress(chosen.index(stage) / len(chosen) if stage in chosen else 0.95, stage)
    )
    assert run.directory is not None  # record_run always returns its run directory
    return {"runs": [_relative(run.directory, out)]}


def ball_game_tvgdd(out: Path, progress: Progress) -> Outputs:
    """TV-GDD on the ball game, through every stage (Zhang, Kong, Niu, section 4, Figs 5-8)."""
    return _run("ball_game", "tvgdd", None, out, progress)


def ball_game_pinv(out: Path, progress: Progress) -> Outputs:
    """The pseudoinverse baseline on the ball game, IK only (Figs 3-4)."""
    return _run("ball_game", "pinv", ("path", "ik"), out, progress)


def table_i_pose() -> tuple[list[float], float]:
    """The Table I analogue's hand pose (X Y Z [m] ROLL PITCH YAW [rad], in the left arm's base frame) and arm angle [rad]: where this robot's left hand is, and its arm angle, with the arm at the paper's solution 1 joints."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from dualarm.model.kinematics import ChainKinematics
    from dualarm.model.robot import load_robot
    from dualarm.model.srs import SrsKinematics

    chain = load_robot(ROBOT).hand_chain("left")
    q = np.array([TABLE_I_SOLUTION_1])
    T = ChainKinematics.of(chain).poses(q)[0]
    pose = [*T[:3, 3].tolist(), *Rotation.from_matrix(T[:3, :3]).as_euler("xyz").tolist()]
    return [round(v, 6) for v in pose], round(float(SrsKinematics.of(chain).arm_angles(q)[0]), 6)


def table_i(out: Path, progress: Progress) -> Outputs:
    """MC-Inverse Table I: the 8 candidates of one pose at one arm angle, as ``table_i.json`` (the JSON of ``dualarm ik srs --json``)."""
    from dualarm.ik.mc_inverse import candidate_table
    from dualarm.model.robot import load_robot

    pose, psi = table_i_pose()
    data = candidate_table(load_robot(ROBOT).hand_chain("left"), tuple(pose), psi)
    path = out / "table_i.json"
    path.write_text(json.dumps(data, indent=2) + "\n")
    return {"table": _relative(path, out)}


def _consistency(task: str, methods: tuple[str, ...], out: Path, progress: Progress) -> Outputs:
    from dualarm.report.consistency import run_consistency

    done: list[str] = []

    def step(text: str) -> None:
        progress(len(done) / len(methods), text)
        done.append(text)

    result = run_consistency(TASKS / f"{task}.toml", methods, out / "consistency" / task, progress=step)
    return {"table": _relative(result.csv, out), "runs": [_relative(Path(r), out) for r in result.table["run"] if r]}


def triangle_consistency(out: Path, progress: Progress) -> Outputs:
    """Every IK method drawing the triangle 5 times (MC-Inverse V.B, Figs 9-10)."""
    from dualarm.report.consistency import DEFAULT_METHODS

    return _consistency("triangle", DEFAULT_METHODS, out, progress)


def circle_consistency(out: Path, progress: Progress) -> Outputs:
    """Every IK method drawing the circle 5 times (MC-Inverse V.C, Figs 12-13)."""
    from dualarm.report.consistency import DEFAULT_METHODS

    return _consistency("circle", DEFAULT_METHODS, out, progress)


def carry_box(out: Path, progress: Progress) -> Outputs:
    """The dual-arm box carried up and down 5 times: the paper's three methods compared over the repetitions (Fig. 16), and MC-Inverse through every stage (eq 11, Fig. 14)."""
    compared = _consistency("carry_box", CARRY_BOX_METHODS, out, lambda f, text: progress(0.6 * f, text))
    executed = _run("carry_box", "mc-inverse", None, out, lambda f, text: progress(0.6 + 0.4 * f, text))
    return {"table": compared["table"], "runs": [*compared["runs"], *executed["runs"]]}


def bowl_grasp(out: Path, progress: Progress) -> Outputs:
    """MCIKRRT planning the bowl grasp :data:`PLAN_TRIALS` times; the first plan retimed, smoothed, executed and recorded (Li & Liang, section 5)."""
    from dualarm.plan.trials import run_trials

    result = run_trials(
        TASKS / "bowl_grasp.toml",
        "mcikrrt",
        PLAN_TRIALS,
        0,
        out / "plan" / "bowl_grasp-mcikrrt",
        recordings=out / "runs",
        command=["dualarm", "plan", "tasks/bowl_grasp.toml", "--trials", str(PLAN_TRIALS)],
        progress=lambda done, total: progress(0.7 * done / total, f"trial {done}/{total}"),
    )
    return {
        "table": _relative(result.directory / "plan_trials.csv", out),
        "summary": _relative(result.directory / "plan_summary.json", out),
        "runs": [_relative(result.run, out)] if result.run else [],
    }


@dataclass(frozen=True)
class Part:
    """One experiment of the reproduction.

    Attributes:
        name: its name on the command line (``--only``).
        paper: the paper it reproduces.
        title: what it is.
        command: the command that reproduces it alone.
        run: the function that runs it (see the module's docstring).
        seconds: about how long it takes alone on a 2-core machine [s]; the longest start first.
    """

    name: str
    paper: str
    title: str
    command: str
    run: Callable[[Path, Progress], Outputs]
    seconds: float


PARTS = (
    Part("ball-game-tvgdd", "TV-GDD", "ball game, TV-GDD, every stage", "dualarm run tasks/ball_game.toml --ik tvgdd", ball_game_tvgdd, 13),
    Part("ball-game-pinv", "TV-GDD", "ball game, pseudoinverse baseline", "dualarm run tasks/ball_game.toml --ik pinv --stages path,ik", ball_game_pinv, 4),
    Part("table-i", "MC-Inverse", "Table I analogue", "dualarm ik srs robots/humanoid --arm left --pose {pose} --arm-angle {psi} --frame chain", table_i, 1),
    Part("triangle", "MC-Inverse", "triangle drawn 5 times, every IK method", "dualarm consistency tasks/triangle.toml", triangle_consistency, 28),
    Part("circle", "MC-Inverse", "circle drawn 5 times, every IK method", "dualarm consistency tasks/circle.toml", circle_consistency, 18),
    Part(
        "carry-box",
        "MC-Inverse",
        "dual-arm box carried 5 times",
        f"dualarm consistency tasks/carry_box.toml --methods {','.join(CARRY_BOX_METHODS)}; dualarm run tasks/carry_box.toml --ik mc-inverse",
        carry_box,
        15,
    ),
    Part("bowl-grasp", "Li & Liang", f"bowl grasp planned {PLAN_TRIALS} times (MCIKRRT)", f"dualarm plan tasks/bowl_grasp.toml --trials {PLAN_TRIALS}", bowl_grasp, 18),
)
#: Parts by name.
BY_NAME = {p.name: p for p in PARTS}
