"""``dualarm reproduce``: the parts, parts.json, report.md and each paper claim in it.

Every "ours" figure of the report is recomputed here from the recordings with numpy, from the
solvers' own arrays, or from PyBullet (independent forward kinematics); every "paper" figure is
checked against the papers' text (see docs/papers.md), copied here by hand. One reproduction of the
cheap parts (Table I, the ball game with pinv and TV-GDD, two at a time on a Dask LocalCluster) is
shared by most tests.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import DualarmError
from dualarm.record.readback import read_run
from tests.helpers import HUMANOID, REPO, TASKS

runner = CliRunner()

#: The parts the shared reproduction runs.
CHOSEN = ("table-i", "ball-game-pinv", "ball-game-tvgdd")
#: Every part and its paper, as the README and `dualarm reproduce --help` list them.
ALL_PARTS = {
    "ball-game-tvgdd": "TV-GDD",
    "ball-game-pinv": "TV-GDD",
    "table-i": "MC-Inverse",
    "triangle": "MC-Inverse",
    "circle": "MC-Inverse",
    "carry-box": "MC-Inverse",
    "bowl-grasp": "Li & Liang",
}
PAPERS = ("TV-GDD", "MC-Inverse", "Li & Liang")
TVGDD_COMMAND = "dualarm run tasks/ball_game.toml --ik tvgdd"
PINV_COMMAND = "dualarm run tasks/ball_game.toml --ik pinv --stages path,ik"

#: Zhang, Kong, Niu, section 4 (seed 000): MAE, AAE, RMSE [m], T_Ave, T_Sum [s].
PAPER_MAE_M, PAPER_AAE_M, PAPER_RMSE_M = 2.1832e-5, 6.2e-6, 8.41e-6
PAPER_T_AVE_S, PAPER_T_SUM_S = 0.001, 1.12
#: Li & Liang, section 5 (seed 001): "The average planning time is 4,210.88 ms."
PAPER_PLANNING_MS = 4210.88
#: Zou, Min, Xu, Table I (seed 004): solutions 1-4 (rows here), joints 1-7.
PAPER_TABLE_I = np.array(
    [
        [-1.84799, 0.21282, -2.08281, -1.94261, 0.54827, 1.29769, 1.38904],
        [-1.29361, -0.21282, 1.05878, -1.94261, 0.54827, 1.29769, 1.38904],
        [-1.84799, 0.21282, -2.08281, -1.94261, -2.59332, -1.29769, 1.75256],
        [1.29361, -0.21282, 1.05878, -1.94261, -2.59332, -1.29769, 1.75256],
    ]
)
#: "Equal to 5 decimals": half a unit of the 5th decimal, twice (the paper's rounding and that of
#: the 6-decimal analogue pose), so 1e-5 rad.
FIVE_DECIMALS = 1e-5
#: Below this a bound excursion is rounding [rad, rad/s].
ZERO = 1e-9


# --- helpers --------------------------------------------------------------------------------------


def _cells(line: str) -> list[str]:
    parts = re.split(r"(?<!\\)\|", line.strip())
    return [p.strip().replace("\\|", "|") for p in parts[1:-1]]


def sections(report: str) -> dict[str, list[str]]:
    """``## heading`` -> its lines."""
    out: dict[str, list[str]] = {}
    current = None
    for line in report.splitlines():
        if line.startswith("## "):
            current = line[3:].strip()
            out[current] = []
        elif current is not None:
            out[current].append(line)
    return out


def claim_rows(report: str) -> dict[str, list[dict[str, str]]]:
    """Paper -> the rows of its claim table, as dicts."""
    keys = ("where", "claim", "paper", "ours", "comparison", "verdict", "runs", "command")
    rows = {}
    for paper, lines in sections(report).items():
        if paper not in PAPERS:
            continue
        table = [_cells(line) for line in lines if line.startswith("|")]
        assert not table or table[0] == [
            "where",
            "claim",
            "paper",
            "ours",
            "ours against the paper",
            "verdict",
            "runs' verdicts",
            "reproduce alone",
        ], table[:1]
        rows[paper] = [dict(zip(keys, cells, strict=True)) for cells in table[2:]]
    return rows


def one(rows: list[dict[str, str]], text: str) -> dict[str, str]:
    found = [r for r in rows if text in r["claim"]]
    assert len(found) == 1, (text, [r["claim"] for r in rows])
    return found[0]


def verdict(agrees: bool) -> str:
    return "agrees" if agrees else "**differs**"


def reproduce(out: Path, only: str, jobs: int):
    return runner.invoke(app, ["reproduce", "--out", str(out), "--only", only, "--jobs", str(jobs)])


def error_lines(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.strip()]


def tree(directory: Path) -> dict[str, bytes]:
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


def pybullet_limits(sim, joints) -> tuple[np.ndarray, np.ndarray]:
    """Position limits of ``joints`` as PyBullet read them from the URDF [rad]."""
    import pybullet as pb

    info = [pb.getJointInfo(sim.body, sim.joint_index[j], physicsClientId=sim.client) for j in joints]
    return np.array([i[8] for i in info]), np.array([i[9] for i in info])


#: The vertical that spans eq (1)'s reference plane with SW.
VERTICAL = np.array([0.0, 0.0, 1.0])


def arm_angle_eq1(S: np.ndarray, E: np.ndarray, W: np.ndarray, V=VERTICAL) -> float:
    """MC-Inverse eq (1): psi = atan2(-(n_ref x n_arm) . SW/|SW|, n_ref . n_arm), with the
    reference plane spanned by SW and the vertical V and the arm plane by S, E, W (normals
    n_ref = SW x V, n_arm = SE x SW)."""
    sw, se = W - S, E - S
    n_ref = np.cross(sw, V)
    n_ref = n_ref / np.linalg.norm(n_ref)
    n_arm = np.cross(se, sw)
    n_arm = n_arm / np.linalg.norm(n_arm)
    return float(np.arctan2(-np.cross(n_ref, n_arm) @ (sw / np.linalg.norm(sw)), n_ref @ n_arm))


def pybullet_arm_angle(sim, hand: str) -> float:
    """Eq (1) from PyBullet's link frames, in the torso frame: S where the shoulder axes meet (the
    shoulder-yaw link's origin), E on the elbow axis (the forearm's origin), W where the wrist axes
    meet (the forearm-roll link's origin)."""
    torso = np.linalg.inv(sim.link_pose("torso"))

    def at(link: str) -> np.ndarray:
        return (torso @ sim.link_pose(link))[:3, 3]

    return arm_angle_eq1(at(f"{hand}_shoulder_yaw_link"), at(f"{hand}_forearm"), at(f"{hand}_forearm_roll_link"))


def wrapped(a) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * np.asarray(a))))


# --- the shared reproduction --------------------------------------------------------------------


@pytest.fixture(scope="module")
def repro(tmp_path_factory):
    """`dualarm reproduce --only table-i,ball-game-pinv,ball-game-tvgdd --jobs 2` (a Dask LocalCluster of two
    workers)."""
    out = tmp_path_factory.mktemp("reproduce") / "reproduction"
    result = reproduce(out, ",".join(CHOSEN), 2)
    assert result.exit_code == 0, (result.output, result.exception)
    parts = {p["name"]: p for p in json.loads((out / "parts.json").read_text())["parts"]}
    return dataclasses.make_dataclass("Repro", ["out", "result", "parts", "report"])(
        out, result, parts, (out / "report.md").read_text()
    )


def _run_of(repro, part: str):
    return read_run(repro.out / repro.parts[part]["outputs"]["runs"][0])


@pytest.mark.integration
def test_exit_0_report_path_last_parts_json_and_time_table(repro):
    out, result = repro.out, repro.result
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    assert lines[-1] == str(out / "report.md") and Path(lines[-1]).is_file()

    index = json.loads((out / "parts.json").read_text())
    assert index["jobs"] == 2
    assert sorted(p["name"] for p in index["parts"]) == sorted(CHOSEN)
    for p in index["parts"]:
        assert p["status"] == "complete" and p["error"] == "", p
        paths = [v for value in p["outputs"].values() for v in (value if isinstance(value, list) else [value])]
        assert paths, p
        for path in paths:
            assert not Path(path).is_absolute() and (out / path).exists(), path
    assert set(repro.parts["table-i"]["outputs"]) == {"table"}
    for part, stages in (
        ("ball-game-tvgdd", ["path", "ik", "retime", "smooth", "approach", "execute"]),
        ("ball-game-pinv", ["path", "ik"]),
    ):
        (run,) = repro.parts[part]["outputs"]["runs"]
        manifest = json.loads((out / run / "manifest.json").read_text())
        assert manifest["status"] == "complete" and manifest["stages"] == stages
        assert (out / run / "run.mcap").is_file() and (out / run / "metrics.json").is_file()
    assert index["wall_time_s"] >= max(p["seconds"] for p in index["parts"])

    # the time table on stdout: one row per part with its status and seconds from parts.json
    assert "time of each part (2 at a time)" in result.stdout
    for p in index["parts"]:
        row = [line for line in lines if f" {p['name']} " in line]
        assert len(row) == 1 and "complete" in row[0] and f"{p['seconds']:.1f}" in row[0], (p["name"], row)


@pytest.mark.integration
def test_report_sections_not_available_commands_and_links(repro):
    out, report = repro.out, repro.report
    headings = [line[3:] for line in report.splitlines() if line.startswith("## ")]
    assert [h for h in headings if h in PAPERS] == list(PAPERS)
    body = sections(report)
    rows = claim_rows(report)

    # parts not run: said so, in their paper's section, and no claim of theirs appears
    for name, paper in ALL_PARTS.items():
        marked = [line for line in body[paper] if f"(`{name}`): " in line]
        if name in CHOSEN:
            assert not marked and f"(`{name}`): not run" not in report
        else:
            assert len(marked) == 1 and marked[0].endswith(f"(`{name}`): not run (see --only)"), marked
    assert rows["Li & Liang"] == []
    assert not any(
        r["where"].startswith(("V.B", "V.C", "V.D", "section 5", "eq (11)", "section IV")) for r in rows["MC-Inverse"]
    )

    # each row: a verdict and the command that reproduces its part alone, in backticks
    table_i = json.loads((out / "table_i.json").read_text())
    ik_srs = "dualarm ik srs robots/humanoid --arm left --pose "
    for paper in ("TV-GDD", "MC-Inverse"):
        assert rows[paper]
        for r in rows[paper]:
            assert re.fullmatch(r"`dualarm [^`]+`", r["command"]), r
            assert r["verdict"] in ("agrees", "**differs**"), r
    for r in rows["TV-GDD"]:
        assert r["command"].strip("`") == (PINV_COMMAND if r["claim"].startswith("pinv") else TVGDD_COMMAND), r
    assert len(rows["TV-GDD"]) == 11
    for r in rows["MC-Inverse"]:
        command = shlex.split(r["command"].strip("`"))
        assert r["command"].strip("`").startswith(ik_srs), r
        pose = [float(v) for v in command[command.index("--pose") + 1 : command.index("--pose") + 7]]
        assert np.allclose(pose, table_i["pose"], atol=1e-5) and float(
            command[command.index("--arm-angle") + 1]
        ) == pytest.approx(table_i["arm_angle"], abs=1e-6)
    assert len(rows["MC-Inverse"]) == 5

    # the headline counts the verdicts of the tables
    judged = [r for paper in PAPERS for r in rows[paper]]
    agreeing = sum(r["verdict"] == "agrees" for r in judged)
    assert f"{agreeing} of {len(judged)} claims agree." in report

    # every relative link and image points to something that exists in the reproduction
    links = re.findall(r"\]\(([^)\s]+)\)", report)
    images = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", report)
    assert images and links
    for link in links:
        assert not Path(link).is_absolute() and not link.startswith(("http:", "https:")), link
        assert (out / link).exists(), link
    for image in images:
        assert (out / image).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", image
    assert str(out) not in report

    # runs and times: exactly the runs of parts.json, and the seconds of each part
    runs = sorted(r for p in repro.parts.values() for r in p["outputs"].get("runs", []))
    run_rows = [_cells(line) for line in body["Runs"] if line.startswith("| ") and "](" in line]
    assert sorted(re.search(r"\]\(([^)]+)\)", row[1]).group(1) for row in run_rows) == runs
    for row in run_rows:  # each run's verdict, as its manifest holds it
        manifest = json.loads((out / re.search(r"\]\(([^)]+)\)", row[1]).group(1) / "manifest.json").read_text())
        assert row[2].split(": ", 1)[1].split(" ")[0] == manifest["status"], row
    time_rows = {c[0]: c for c in (_cells(line) for line in body["Time of each part"] if line.startswith("| "))}
    for name, p in repro.parts.items():
        assert time_rows[name][2] == "complete" and time_rows[name][3] == f"{p['seconds']:.1f}"


# --- TV-GDD ---------------------------------------------------------------------------------------


@pytest.mark.integration
def test_tvgdd_hand_error_and_time_claims_from_the_recording(repro):
    rows = claim_rows(repro.report)["TV-GDD"]
    run = _run_of(repro, "ball-game-tvgdd")
    sample = run["/ik/sample"]
    assert run.manifest["settings"]["ik"]["method"] == "tvgdd"
    errors = sample[["hand_error_m.left", "hand_error_m.right"]].to_numpy()
    solve = sample["solve_time_s"].to_numpy()
    largest = errors.max()
    mean = errors.mean(axis=0).max()
    rms = np.sqrt((errors**2).mean(axis=0)).max()
    assert (errors >= 0).all() and (solve > 0).all() and len(sample) == 1801

    for text, paper, ours, unit, suffix in (
        ("largest hand position error (MAE)", PAPER_MAE_M, largest, "m", ""),
        ("mean hand position error (AAE)", PAPER_AAE_M, mean, "m", " (the larger hand)"),
        ("RMS hand position error", PAPER_RMSE_M, rms, "m", " (the larger hand)"),
        ("T_ave", PAPER_T_AVE_S, solve.mean(), "s", ""),
        ("T_sum", PAPER_T_SUM_S, solve.sum(), "s", ""),
    ):
        row = one(rows, text)
        assert row["ours"] == f"{ours:.3g} {unit}{suffix}", (row, ours)
        value, shown_unit = row["paper"].split()
        assert float(value) == paper and shown_unit == unit, row
        assert row["verdict"] == verdict(ours <= paper), row
        ratio = f"ours / paper = {ours / paper:.2f}" if unit == "m" else f"paper / ours = {paper / ours:.0f}x"
        assert row["comparison"] == ratio, row

    # the recorded metrics agree with the recorded samples
    assert run.metrics["ik.position_error_max_m"] == pytest.approx(largest, rel=1e-12)
    assert run.metrics["ik.solve_time_total_s"] == pytest.approx(solve.sum(), rel=1e-9)
    assert run.metrics["ik.solve_time_mean_s"] == pytest.approx(solve.mean(), rel=1e-9)


@pytest.mark.integration
def test_tvgdd_recorded_hand_errors_are_pybullets(repro):
    """The hand_error_m columns behind Fig. 8's claims: |reference - f(q)| with f from PyBullet."""
    from dualarm.sim.world import load_pybullet_robot

    run = _run_of(repro, "ball-game-tvgdd")
    sample = run["/ik/sample"]
    start = run["/task/joint_state"].iloc[0]
    everything = [c.split(".", 1)[1] for c in start.index if c.startswith("position.")]
    joints = [c.split(".", 1)[1] for c in sample.columns if c.startswith("position.")]
    references = {h: run[f"/task/reference/{h}"] for h in ("left", "right")}
    for ref in references.values():
        assert np.allclose(ref["t"].to_numpy(), sample["t"].to_numpy()) and set(ref["frame_id"]) == {"base_link"}
    worst = 0.0
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        sim.set_positions(everything, [start[f"position.{j}"] for j in everything])
        for k in range(0, len(sample), 25):
            sim.set_positions(joints, sample.iloc[k][[f"position.{j}" for j in joints]].to_numpy(float))
            base = np.linalg.inv(sim.link_pose("base_link"))
            for hand, ref in references.items():
                reached = (base @ sim.link_pose(f"{hand}_hand"))[:3, 3]
                wanted = ref.iloc[k][["position.x", "position.y", "position.z"]].to_numpy(float)
                worst = max(worst, abs(np.linalg.norm(wanted - reached) - sample.iloc[k][f"hand_error_m.{hand}"]))
    assert worst < 5e-7  # PyBullet's single precision


@pytest.mark.integration
def test_tvgdd_bound_execution_claims_from_the_recording(repro):
    from dualarm.sim.world import load_pybullet_robot

    rows = claim_rows(repro.report)["TV-GDD"]
    run = _run_of(repro, "ball-game-tvgdd")
    sample, bounds, limits = run["/ik/sample"], run["/ik/bounds"], run["/ik/limits"].iloc[0]
    joints = [c.split(".", 1)[1] for c in sample.columns if c.startswith("position.")]
    assert len(joints) == 14 and np.allclose(bounds["t"].to_numpy(), sample["t"].to_numpy())
    q = sample[[f"position.{j}" for j in joints]].to_numpy()
    qd = sample[[f"velocity.{j}" for j in joints]].to_numpy()
    lo, hi = (bounds[[f"theta_{s}.{j}" for j in joints]].to_numpy() for s in ("lower", "upper"))
    zlo, zhi = (bounds[[f"zeta_{s}.{j}" for j in joints]].to_numpy() for s in ("lower", "upper"))

    position = np.maximum(lo - q, q - hi).max()
    row = one(rows, "TV-GDD's joints stay within")
    assert (row["ours"] == "none") == (position <= ZERO) and row["verdict"] == verdict(position <= ZERO), (
        row,
        position,
    )
    if position > ZERO:
        assert row["ours"].startswith(f"{position:.3g} rad (")

    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        lower, upper = pybullet_limits(sim, joints)
    vmax = np.array([limits[f"velocity.{j}"] for j in joints])
    velocity = np.maximum(zlo - qd, qd - zhi).max()
    physical = max(np.maximum(lower - q, q - upper).max(), (np.abs(qd) - vmax).max())
    row = one(rows, "TV-GDD's velocities stay within")
    assert row["ours"].startswith("ζ±: none;") == (velocity <= ZERO), (row, velocity)
    assert row["ours"].endswith("physical: none") == (physical <= ZERO), (row, physical)
    assert row["verdict"] == verdict(max(velocity, physical) <= ZERO)

    # the bounds that close are the paper's joints 6, 7, 13 and 14; when they are 99 % closed
    t = bounds["t"].to_numpy()
    width = hi - lo
    closing = [i for i in range(len(joints)) if width[-1, i] <= 1e-6 * width[0, i]]
    assert closing == [5, 6, 12, 13]
    latest = max(t[np.flatnonzero(width[:, i] <= 0.01 * width[0, i])[0]] for i in closing)
    row = one(rows, "close after about 5 s")
    assert row["ours"] == f"{latest:.2f} s, 99 % closed ({', '.join(joints[i] for i in closing)})", row
    assert row["comparison"] == f"{latest - 5:+.2f} s" and row["verdict"] == verdict(abs(latest - 5) <= 1)

    # Fig. 7: executed in PyBullet
    executed = run["/execute/sample"]
    tracking = executed[["hand_error_m.left", "hand_error_m.right"]].to_numpy().max()
    contacts = int(((executed["self_contacts"] > 0) | (executed["environment_contacts"] > 0)).sum())
    row = one(rows, "the motion runs on the robot")
    assert (
        row["ours"]
        == f"executed in PyBullet: tracking error {tracking * 1e6:.2f} µm, {contacts} steps with unexpected contacts"
    ), row
    assert row["verdict"] == verdict(contacts == 0 and tracking < 1e-3)


@pytest.mark.integration
def test_pinv_excursion_claims_equal_the_solvers_arrays(repro):
    from dualarm.ik.velocity.pinv import settings_for, solve_pinv
    from dualarm.paths import build_reference
    from dualarm.tasks import load_task

    rows = claim_rows(repro.report)["TV-GDD"]
    task = load_task(TASKS / "ball_game.toml")
    path = solve_pinv(task.robot, build_reference(task), task.initial_q, settings_for(task))
    recorded = _run_of(repro, "ball-game-pinv")["/ik/sample"]
    assert np.abs(recorded[[f"position.{j}" for j in path.joint_names]].to_numpy() - path.q).max() < 1e-12
    for text, values, lower, upper, unit in (
        ("pinv's joints leave", path.q, "theta_lower", "theta_upper", "rad"),
        ("pinv's joint velocities exceed", path.qd, "zeta_lower", "zeta_upper", "rad/s"),
    ):
        outside = np.maximum(path.extras[lower] - values, values - path.extras[upper])
        j = int(np.argmax(outside.max(axis=0)))
        largest = outside[:, j].max()
        first = path.t[np.flatnonzero(outside[:, j] > ZERO)[0]]
        row = one(rows, text)
        assert largest > 0.01  # the paper's Figs 3-4: pinv leaves the bands
        assert row["ours"] == f"{largest:.3g} {unit} ({path.joint_names[j]}, first at {first:.2f} s)", row
        assert row["verdict"] == "agrees" and row["comparison"] == "outside by more than 0"


# --- MC-Inverse, Table I --------------------------------------------------------------------------


@pytest.mark.integration
def test_table_i_candidates_reach_the_analogue_pose_in_pybullet(repro):
    from dualarm.reproduce.claims import PAPER_TABLE_I as QUOTED
    from dualarm.reproduce.experiments import TABLE_I_SOLUTION_1
    from dualarm.sim.world import load_pybullet_robot

    data = json.loads((repro.out / "table_i.json").read_text())
    joints, candidates = data["chain"]["joints"], data["candidates"]
    assert data["chain"]["base"] == "torso" and data["chain"]["tip"] == "left_hand" and len(joints) == 7
    assert np.array_equal(TABLE_I_SOLUTION_1, PAPER_TABLE_I[0]) and np.array_equal(QUOTED, PAPER_TABLE_I)
    target = np.eye(4)
    target[:3, :3] = Rotation.from_euler("xyz", data["pose"][3:]).as_matrix()
    target[:3, 3] = data["pose"][:3]
    assert len(candidates) == 8
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:

        def hand() -> np.ndarray:
            return np.linalg.inv(sim.link_pose("torso")) @ sim.link_pose("left_hand")

        # the analogue: the hand pose and arm angle at the paper's solution 1
        sim.set_positions(joints, PAPER_TABLE_I[0])
        at_solution_1 = hand()
        assert np.abs(at_solution_1[:3, 3] - target[:3, 3]).max() < 1e-6
        assert np.abs(at_solution_1[:3, :3] - target[:3, :3]).max() < 2e-6
        assert wrapped(pybullet_arm_angle(sim, "left") - data["arm_angle"]) < 1e-6

        lower, upper = pybullet_limits(sim, joints)
        for c in candidates:
            sim.set_positions(joints, c["q"])
            reached = hand()
            assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-6, c
            assert np.abs(reached[:3, :3] - target[:3, :3]).max() < 2e-6, c
            psi = pybullet_arm_angle(sim, "left")
            assert wrapped(psi - data["arm_angle"]) < 1e-6 and wrapped(psi - c["arm_angle_rad"]) < 1e-6, (psi, c)
            assert c["valid"] == bool(np.all((np.array(c["q"]) >= lower) & (np.array(c["q"]) <= upper))), c
    # the 8 are distinct, and all share the elbow's magnitude
    q = np.array([c["q"] for c in candidates])
    assert len({tuple(np.round(row, 6)) for row in q}) == 8
    assert np.ptp(np.abs(q[:, 3])) < 1e-9


@pytest.mark.integration
def test_table_i_rows_of_the_report_count_what_the_table_holds(repro):
    data = json.loads((repro.out / "table_i.json").read_text())
    rows = claim_rows(repro.report)["MC-Inverse"]
    q = np.array([c["q"] for c in data["candidates"]])
    valid = np.array([c["valid"] for c in data["candidates"]])
    psi = np.array([c["arm_angle_rad"] for c in data["candidates"]])

    row = one(rows, "give 8 candidate solutions")
    assert row["paper"] == "8" and row["ours"] == str(len(q)) and row["verdict"] == verdict(len(q) == 8)

    bent_like_hr2 = valid & (q[:, 3] < 0)
    row = one(rows, "of them are valid")
    assert (
        row["paper"] == "4"
        and row["ours"] == f"{valid.sum()} ({bent_like_hr2.sum()} with the paper's elbow sign θ4 < 0)"
    ), row
    assert row["verdict"] == verdict(valid.sum() == 4)

    row = one(rows, "have the arm angle asked for")
    spread = np.abs(psi[valid] - data["arm_angle"]).max()
    assert row["ours"] == f"largest |ψ(q) − ψ| = {spread:.2g} rad" and row["verdict"] == verdict(spread <= ZERO), row

    row = one(rows, "share θ4")
    elbows = q[bent_like_hr2, 3]
    assert (
        row["ours"].startswith(f"θ4 = {elbows[0]:.5f} in all {len(elbows)} (spread ")
        and f"{elbows[0]:.5f}" == "-1.94261"
    )

    # each of the paper's solutions against the candidate that matches most of its 7 values
    equal, sign_only, others = 0, [], 0
    for j, paper in enumerate(PAPER_TABLE_I):
        best = max(range(len(q)), key=lambda i: (np.sum(np.abs(q[i] - paper) <= FIVE_DECIMALS), -i))
        for k in range(7):
            if abs(q[best, k] - paper[k]) <= FIVE_DECIMALS:
                equal += 1
            elif abs(q[best, k] + paper[k]) <= FIVE_DECIMALS:
                sign_only.append(f"solution {j + 1} θ{k + 1}")
            else:
                others += 1
    assert (equal, len(sign_only), others) == (25, 3, 0)  # the structure the seeds README describes
    row = one(rows, "the joint values of the 4 solutions")
    assert row["paper"] == "28 values"
    assert (
        row["ours"]
        == f"{equal} of 28 equal to 5 decimals; {len(sign_only)} equal but for the sign ({', '.join(sign_only)});"
        f" {others} others"
    ), row
    assert row["verdict"] == verdict(others == 0)

    # the report's own Table I lists ours and the paper's
    table = [_cells(line) for line in sections(repro.report)["Table I, ours and the paper's"] if line.startswith("| ")]
    ours = [r for r in table if r[0].isdigit()]
    theirs = [r for r in table if r[0].startswith("paper")]
    assert len(ours) == 8 and len(theirs) == 4
    assert np.allclose([[float(v) for v in r[1:8]] for r in theirs], PAPER_TABLE_I, atol=0)
    assert np.allclose([[float(v) for v in r[1:8]] for r in ours], q, atol=5e-6)


def _table_i_command(repro) -> list[str]:
    row = one(claim_rows(repro.report)["MC-Inverse"], "give 8 candidate solutions")
    return shlex.split(row["command"].strip("`"))[1:]


@pytest.mark.integration
def test_table_i_command_of_the_report_reproduces_the_table(repro, monkeypatch):
    monkeypatch.chdir(REPO)  # the command names robots/humanoid relative to the repository
    result = runner.invoke(app, [*_table_i_command(repro), "--json"])
    assert result.exit_code == 0, result.output
    again = json.loads(result.stdout)
    data = json.loads((repro.out / "table_i.json").read_text())
    assert [c["valid"] for c in again["candidates"]] == [c["valid"] for c in data["candidates"]]
    assert (
        np.abs(np.array([c["q"] for c in again["candidates"]]) - np.array([c["q"] for c in data["candidates"]])).max()
        < FIVE_DECIMALS / 2
    )


@pytest.mark.integration
def test_table_i_command_of_the_report_runs_the_parts_exact_pose(repro):
    command = _table_i_command(repro)
    data = json.loads((repro.out / "table_i.json").read_text())
    pose = [float(v) for v in command[command.index("--pose") + 1 : command.index("--pose") + 7]]
    assert pose == data["pose"] and float(command[command.index("--arm-angle") + 1]) == data["arm_angle"]


# --- failures and re-runs -------------------------------------------------------------------------


def test_unknown_part_is_one_line_naming_the_parts(tmp_path):
    result = reproduce(tmp_path / "out", "nonsense", 1)
    assert result.exit_code == 2
    lines = error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "'nonsense'" in lines[0], result.stderr
    assert all(name in lines[0] for name in ALL_PARTS)
    assert "Traceback" not in result.output and not (tmp_path / "out").exists()


def test_out_that_is_not_a_reproduction_is_refused_and_left_alone(tmp_path):
    mine = tmp_path / "mine"
    (mine / "sub").mkdir(parents=True)
    (mine / "notes.txt").write_text("keep me\n")
    (mine / "sub" / "data.csv").write_text("a,b\n1,2\n")
    before = tree(mine)
    result = reproduce(mine, "table-i", 1)
    assert result.exit_code == 2
    lines = error_lines(result)
    assert (
        len(lines) == 1
        and lines[0].startswith("error: ")
        and str(mine) in lines[0]
        and "not a reproduction" in lines[0]
    ), result.stderr
    assert tree(mine) == before and "Traceback" not in result.output

    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    result = reproduce(a_file, "table-i", 1)
    assert result.exit_code == 2 and len(error_lines(result)) == 1 and a_file.read_text() == "x"


@pytest.mark.integration
def test_second_reproduction_replaces_the_first(repro, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(repro.out, out)
    old_runs = [r for p in repro.parts.values() for r in p["outputs"].get("runs", [])]
    assert old_runs and all((out / r).is_dir() for r in old_runs)
    result = reproduce(out, "table-i", 1)
    assert result.exit_code == 0, result.output
    assert not any((out / r).exists() for r in old_runs) and not (out / "runs").exists()
    assert not (out / "figures" / "ball-game-tvgdd").exists()
    index = json.loads((out / "parts.json").read_text())
    assert [p["name"] for p in index["parts"]] == ["table-i"] and index["jobs"] == 1
    report = (out / "report.md").read_text()
    rows = claim_rows(report)
    assert rows["TV-GDD"] == [] and len(rows["MC-Inverse"]) == 5
    assert "(`ball-game-tvgdd`): not run (see --only)" in report and "runs/" not in report


def _boom(out, robot, progress):
    raise DualarmError("ball_game.toml: the simulator caught fire")


@pytest.fixture(scope="module")
def failed_repro(tmp_path_factory):
    """A reproduction whose TV-GDD part raises (in this process: --jobs 1)."""
    from dualarm.reproduce import experiments

    out = tmp_path_factory.mktemp("failed") / "reproduction"
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(
            experiments.BY_NAME,
            "ball-game-tvgdd",
            dataclasses.replace(experiments.BY_NAME["ball-game-tvgdd"], run=_boom),
        )
        result = reproduce(out, "table-i,ball-game-tvgdd,ball-game-pinv", 1)
    return out, result


@pytest.mark.integration
def test_a_failing_part_exits_1_and_is_reported_failed(failed_repro):
    out, result = failed_repro
    assert result.exit_code == 1, (result.output, result.exception)
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    assert lines[-1] == str(out / "report.md")
    assert any(
        "ball-game-tvgdd" in line and "failed: ball_game.toml: the simulator caught fire" in line for line in lines
    )
    parts = {p["name"]: p for p in json.loads((out / "parts.json").read_text())["parts"]}
    assert (
        parts["ball-game-tvgdd"]["status"] == "failed"
        and parts["ball-game-tvgdd"]["error"] == "ball_game.toml: the simulator caught fire"
    )
    assert parts["ball-game-tvgdd"]["outputs"] == {}
    assert parts["table-i"]["status"] == parts["ball-game-pinv"]["status"] == "complete"

    report = (out / "report.md").read_text()
    body, rows = sections(report), claim_rows(report)
    assert any(
        line.endswith("(`ball-game-tvgdd`): failed: ball_game.toml: the simulator caught fire")
        for line in body["TV-GDD"]
    )
    assert not any(r["command"] == f"`{TVGDD_COMMAND}`" for r in rows["TV-GDD"])  # nothing of TV-GDD's is made up
    assert "figures/ball-game-tvgdd" not in report
    assert [r["claim"] for r in rows["MC-Inverse"]] == [
        "one pose and arm angle give 8 candidate solutions",
        "4 of them are valid",
        "the valid solutions have the arm angle asked for",
        "the valid solutions share θ4 and differ only at the shoulder and the wrist",
        "the joint values of the 4 solutions",
    ]
    time_rows = {c[0]: c for c in (_cells(line) for line in body["Time of each part"] if line.startswith("| "))}
    assert time_rows["ball-game-tvgdd"][2] == "failed"


@pytest.mark.integration
def test_the_completed_pinv_part_keeps_its_claims_when_tvgdd_fails(failed_repro):
    out, _ = failed_repro
    rows = claim_rows((out / "report.md").read_text())["TV-GDD"]
    assert {r["where"] for r in rows if r["command"] == f"`{PINV_COMMAND}`"} == {"Fig. 3", "Fig. 4"}


@pytest.mark.integration
def test_a_run_that_fails_at_its_stage_is_kept_and_contradicts_its_claims(tmp_path, monkeypatch):
    """The ball game with 0.01 rad/s velocity limits: TV-GDD is infeasible at a step (a run recorded as
    failed, as a robot it cannot move would give). The part still ends, its failed run is listed,
    the claim resting on it is contradicted with the run's own error, and the command exits 3 (not
    1, which is for a part that could not run)."""
    from dualarm.reproduce import experiments

    tasks = tmp_path / "tasks"
    tasks.mkdir()
    text = (TASKS / "ball_game.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    assert "\nvelocity = 6.0\n" in text
    (tasks / "ball_game.toml").write_text(text.replace("\nvelocity = 6.0\n", "\nvelocity = 0.01\n"))
    monkeypatch.setattr(experiments, "TASKS", tasks)
    out = tmp_path / "reproduction"
    result = reproduce(out, "ball-game-tvgdd", 1)
    assert result.exit_code == 3, (result.output, result.exception)
    parts = {p["name"]: p for p in json.loads((out / "parts.json").read_text())["parts"]}
    (run_path,) = parts["ball-game-tvgdd"]["outputs"]["runs"]
    run = read_run(out / run_path)
    assert parts["ball-game-tvgdd"]["status"] == "complete" and run.status == "failed"
    assert "TV-GDD step" in run.error and "infeasible" in run.error
    (row,) = claim_rows((out / "report.md").read_text())["TV-GDD"]
    assert row["ours"] == "not available: the tvgdd run failed (see its manifest)"
    assert row["runs"].startswith("**contradicted:** tvgdd: failed (TV-GDD step 22 (t = 0.220 s) is infeasible")
    assert any(line.startswith("contradicted: TV-GDD Figs 5-8") for line in error_lines(result))


@pytest.mark.integration
def test_a_part_whose_path_leaves_the_robots_reach_is_not_available(tmp_path, monkeypatch):
    """The ball game whose first stroke goes 2 m up: the task loads (its waypoints are the start), but the path
    stage refuses the path (as on a Baxter, whose right hand cannot follow the strokes from its ready pose). The
    part is not available, with the path stage's reason, not failed: exit 2 when it is the only part."""
    from dualarm.reproduce import experiments

    tasks = tmp_path / "tasks"
    tasks.mkdir()
    text = (TASKS / "ball_game.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    stroke = "left = { by = [0.0, 0.0, 0.10] }\nright = { by = [0.0, 0.0, 0.10] }"
    assert stroke in text
    (tasks / "ball_game.toml").write_text(text.replace(stroke, stroke.replace("0.10", "2.0"), 1))
    monkeypatch.setattr(experiments, "TASKS", tasks)
    out = tmp_path / "reproduction"
    result = reproduce(out, "ball-game-pinv", 1)
    assert result.exit_code == 2, (result.output, result.exception)
    (part,) = json.loads((out / "parts.json").read_text())["parts"]
    assert part["status"] == "not available" and part["outputs"] == {}
    assert (
        part["error"].startswith("its task's path is out of this robot's reach: ") and "cannot reach" in part["error"]
    )


@pytest.mark.integration
def test_one_at_a_time_is_not_said_to_share_the_machine(failed_repro):
    out, _ = failed_repro
    report = (out / "report.md").read_text()
    assert "ran 1 at a time" in report
    assert "measured with another part running" not in report


@pytest.mark.integration
def test_report_rewritten_from_a_copy_is_the_same(repro, tmp_path):
    from dualarm.reproduce.report import write_reproduction_report

    copy = tmp_path / "copied"
    shutil.copytree(repro.out, copy)
    (copy / "report.md").unlink()
    shutil.rmtree(copy / "figures")
    path = write_reproduction_report(copy)
    assert path == copy / "report.md"
    again = path.read_text()
    assert claim_rows(again) == claim_rows(repro.report)
    assert again == repro.report
    for link in re.findall(r"\]\(([^)\s]+)\)", again):
        assert (copy / link).exists(), link


# --- consistency and planning claims on cheap inputs ----------------------------------------------


@pytest.fixture(scope="module")
def carry_box_runs(tmp_path_factory):
    """The carry_box IK of the paper's three methods, 2 repetitions each (the consistency stages)."""
    from dualarm.run import record_run
    from dualarm.tasks import load_task

    out = tmp_path_factory.mktemp("carry_box")
    return [
        read_run(record_run(load_task(TASKS / "carry_box.toml", 2), m, stages=("path", "ik"), out_dir=out).directory)
        for m in ("mc-inverse", "trac-ik", "ikfast-style")
    ]


def _deviations(run, task_file: Path) -> tuple[float, float]:
    """(largest |q_r - q_0|, largest wrapped |psi_r - psi_0|) between samples at the same place of
    repetition r and of the first, where both succeeded."""
    spec = tomllib.loads(task_file.read_text())
    period = spec["control_period_s"]
    length = sum(m["duration_s"] for m in spec["moves"])
    sample = run["/ik/sample"]
    rep, t, ok = sample["rep"].to_numpy(), sample["t"].to_numpy(), sample["status"].to_numpy() == 0
    q = sample[[c for c in sample.columns if c.startswith("position.")]].to_numpy()
    psi = sample[["arm_angle_rad.left", "arm_angle_rad.right"]].to_numpy()
    first = np.flatnonzero(rep == 0)
    assert np.allclose(t[first], np.arange(len(first)) * period)
    dq, dpsi = 0.0, 0.0
    for k in np.flatnonzero(rep > 0):
        i = first[int(round((t[k] - rep[k] * length) / period))]
        if ok[k] and ok[i]:
            dq = max(dq, np.abs(q[k] - q[i]).max())
            dpsi = max(dpsi, wrapped(psi[k] - psi[i]).max())
    return float(dq), float(dpsi)


@pytest.mark.integration
def test_consistency_claims_show_the_deviations_of_the_recordings(carry_box_runs):
    from dualarm.reproduce.claims import consistency_claims

    found = {}
    for run in carry_box_runs:
        method = run.manifest["settings"]["ik"]["method"]
        # TRAC-IK may fail a sample now and then (its timeout is wall-clock): a violated run, still judged
        assert run.status == ("complete" if method != "trac-ik" else run.status) and run.status in (
            "complete",
            "violated",
        )
        assert sorted(run["/ik/sample"]["rep"].unique()) == [0, 1]
        dq, dpsi = _deviations(run, TASKS / "carry_box.toml")
        assert run.metrics["ik.rep_joint_deviation_max_rad"] == pytest.approx(dq, rel=1e-12, abs=1e-15), method
        assert run.metrics["ik.rep_arm_angle_deviation_max_rad"] == pytest.approx(dpsi, rel=1e-9, abs=1e-15), method
        found[method] = (dq, dpsi)

    claims = consistency_claims("carry_box", carry_box_runs)
    assert [c.where for c in claims] == ["V.D, Fig. 16"] * 2 and {c.part for c in claims} == {"carry-box"}
    mc, box = claims

    def shown(method: str) -> str:
        return f"Δq {found[method][0]:.2g} rad, Δψ {found[method][1]:.2g} rad"

    assert mc.ours == shown("mc-inverse") and mc.agrees == (max(found["mc-inverse"]) <= ZERO)
    assert box.ours == f"TRAC-IK {shown('trac-ik')}; ikfast-style {shown('ikfast-style')}"
    assert box.agrees == (0.01 < found["ikfast-style"][1] < found["trac-ik"][1])


@pytest.mark.integration
def test_recorded_arm_angles_are_eq1_of_pybullets_frames(carry_box_runs):
    """The arm_angle_rad columns behind the Δψ figures, against eq (1) implemented here."""
    from dualarm.sim.world import load_pybullet_robot

    run = next(r for r in carry_box_runs if r.manifest["settings"]["ik"]["method"] == "trac-ik")
    sample, start = run["/ik/sample"], run["/task/joint_state"].iloc[0]
    everything = [c.split(".", 1)[1] for c in start.index if c.startswith("position.")]
    joints = [c.split(".", 1)[1] for c in sample.columns if c.startswith("position.")]
    worst = 0.0
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        sim.set_positions(everything, [start[f"position.{j}"] for j in everything])
        for k in range(0, len(sample), 40):
            sim.set_positions(joints, sample.iloc[k][[f"position.{j}" for j in joints]].to_numpy(float))
            for hand in ("left", "right"):
                worst = max(
                    worst, float(wrapped(pybullet_arm_angle(sim, hand) - sample.iloc[k][f"arm_angle_rad.{hand}"]))
                )
    assert worst < 1e-6


@pytest.mark.integration
def test_consistency_claims_survive_a_failed_method_run(carry_box_runs, tmp_path):
    from dualarm.reproduce.claims import consistency_claims
    from dualarm.run import record_run
    from dualarm.tasks import load_task

    task = tmp_path / "carry_box.toml"
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    task.write_text(text.replace("[arm_angle]\n", "[arm_angle]\nmax_joint_step_rad = 1e-6\n"))
    with pytest.raises(DualarmError, match="max_joint_step_rad"):
        record_run(load_task(task, 2), "mc-inverse", stages=("path", "ik"), out_dir=tmp_path / "runs")
    (failed_dir,) = (tmp_path / "runs").glob("*/*")
    failed = read_run(failed_dir)
    assert failed.status == "failed"
    others = [r for r in carry_box_runs if r.manifest["settings"]["ik"]["method"] != "mc-inverse"]
    claims = consistency_claims("carry_box", [failed, *others])
    mc = next(c for c in claims if "MC-Inverse repeats" in c.claim)
    assert mc.agrees is not True


def test_plan_claims_count_successes_and_average_their_times():
    from dualarm.reproduce.claims import plan_claims

    trials = pd.DataFrame(
        {"success": [True, False, True, True, False], "planning_time_s": [0.120, 5.0, 0.030, 0.060, 5.0]}
    )
    found, mean = plan_claims(trials, None)
    assert found.ours == "3 of 5 trials" and found.agrees is True and found.part == "bowl-grasp"
    assert mean.theirs == f"{PAPER_PLANNING_MS:.2f} ms (i7-3770)"
    assert mean.ours == "70.0 ms (median 60.0 ms)"  # (120 + 30 + 60) / 3; the failures' 5 s left out
    assert mean.comparison == f"paper / ours = {PAPER_PLANNING_MS / 70.0:.0f}x" and mean.agrees is True

    slow = pd.DataFrame({"success": [True, True], "planning_time_s": [5.0, 6.0]})
    _, mean = plan_claims(slow, None)
    assert mean.ours == "5500.0 ms (median 5500.0 ms)" and mean.agrees is False

    none = pd.DataFrame({"success": [False, False, False], "planning_time_s": [5.0, 5.0, 5.0]})
    (only,) = plan_claims(none, None)
    assert only.ours == "0 of 3 trials" and only.agrees is False


def test_an_interrupted_reproduction_is_recognised_and_emptied(tmp_path):
    """A reproduction stopped before parts.json and report.md (Ctrl-C) is still recognised as one
    by the marker written first, so the next run empties it instead of refusing it."""
    from dualarm.record.run_dir import RunDirectory
    from dualarm.reproduce.runner import MARKER, prepare

    out = tmp_path / "repro"
    prepare(out)
    staging = RunDirectory.create(
        out / "runs", "triangle", {}
    ).staging  # a run stopped before it was renamed into place
    (staging / "run.mcap").write_bytes(b"half")
    prepare(out)
    assert [p.name for p in out.iterdir()] == [MARKER]


@pytest.mark.integration
def test_a_claim_resting_on_a_violated_mc_inverse_run_is_contradicted(carry_box_runs, tmp_path):
    """The box lifted in 0.2 s instead of 2 s: MC-Inverse still repeats, but at the task's timing
    its joints outrun their velocity limits (finite differences of the recorded joints), so the
    run is violated and the claim that rests on it is contradicted, not agreed."""
    from dualarm.model.robot import load_robot
    from dualarm.reproduce.claims import consistency_claims
    from dualarm.run import record_run
    from dualarm.tasks import load_task

    task = tmp_path / "carry_box.toml"
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    task.write_text(text.replace("duration_s = 2.0", "duration_s = 0.2"))
    fast = read_run(
        record_run(load_task(task, 2), "mc-inverse", stages=("path", "ik"), out_dir=tmp_path / "runs").directory
    )
    sample = fast["/ik/sample"]
    joints = [c.split(".", 1)[1] for c in sample.columns if c.startswith("position.")]
    speed = np.abs(np.diff(sample[[f"position.{j}" for j in joints]].to_numpy(), axis=0)).max(axis=0) / 0.01
    assert (speed > load_robot(HUMANOID).limit_array("velocity", tuple(joints))).any()
    assert fast.status == "violated" and fast.violations[0].startswith("ik: velocity of ")
    others = [r for r in carry_box_runs if r.manifest["settings"]["ik"]["method"] != "mc-inverse"]
    mc = next(c for c in consistency_claims("carry_box", [fast, *others]) if "MC-Inverse repeats" in c.claim)
    assert mc.contradicted and mc.agrees is False and mc.verdict.startswith("mc-inverse: violated (ik: velocity of ")
    box = next(c for c in consistency_claims("carry_box", carry_box_runs) if "MC-Inverse repeats" in c.claim)
    assert not box.contradicted and box.verdict == "mc-inverse: complete"


@pytest.mark.integration
def test_on_a_separately_started_cluster_the_parts_are_those_of_a_local_one(repro, tmp_path):
    """`--scheduler`: a scheduler and two `dask worker` processes started apart on 127.0.0.1 (two nodes sharing the file
    system) run the parts; Table I and the pinv run's metrics are the shared reproduction's (a LocalCluster)."""
    from dualarm.bench.study import loopback_cluster
    from dualarm.study.run import VARYING

    out = tmp_path / "cluster"
    with loopback_cluster(2, tmp_path) as address:
        result = runner.invoke(
            app, ["reproduce", "--out", str(out), "--only", "table-i,ball-game-pinv", "--scheduler", address]
        )
    assert result.exit_code == 0, (result.output, result.exception)
    index = json.loads((out / "parts.json").read_text())
    assert index["scheduler"] == address and index["jobs"] == 2
    assert [p["status"] for p in index["parts"]] == ["complete", "complete"]
    assert json.loads((out / "table_i.json").read_text()) == json.loads((repro.out / "table_i.json").read_text())
    (run,) = index["parts"][0]["outputs"]["runs"]
    ours, local = (
        json.loads((d / "metrics.json").read_text())
        for d in (out / run, repro.out / repro.parts["ball-game-pinv"]["outputs"]["runs"][0])
    )
    assert {k: v for k, v in ours.items() if k not in VARYING} == {k: v for k, v in local.items() if k not in VARYING}


@pytest.mark.integration
def test_a_worker_that_does_not_see_out_is_refused_in_one_line(tmp_path):
    """A worker in its own mount namespace, where a tmpfs hides ``out``'s directory (a node without the shared file
    system): exit 2, one line naming the worker and why."""
    import subprocess
    import sys

    from distributed import Client

    from dualarm.bench.study import loopback_cluster

    hidden = tmp_path / "hidden"
    hidden.mkdir()
    if subprocess.run(["unshare", "--mount", "true"], capture_output=True).returncode != 0:
        pytest.skip("needs unshare --mount (root, Linux)")
    with loopback_cluster(0, tmp_path) as address:
        worker = (
            f"mount -t tmpfs none {shlex.quote(str(hidden))} && exec {shlex.quote(sys.executable)}"
            f" -m distributed.cli.dask_worker {address} --nthreads 1 --name elsewhere --no-dashboard"
        )
        process = subprocess.Popen(
            ["unshare", "--mount", "--propagation", "private", "sh", "-c", worker],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            with Client(address, timeout="60s") as client:
                client.wait_for_workers(1, timeout=60)
            result = runner.invoke(
                app, ["reproduce", "--out", str(hidden / "repro"), "--only", "table-i", "--scheduler", address]
            )
        finally:
            process.terminate()
            process.wait(timeout=30)
    assert result.exit_code == 2, result.output
    assert error_lines(result) == [
        f"error: worker elsewhere does not see {hidden / 'repro'}: with --scheduler, --out must be on a file system"
        " the workers share"
    ]
    assert not (hidden / "repro" / "parts.json").exists()


@pytest.mark.integration
def test_a_consistency_claim_whose_metric_a_robot_cannot_give_says_why(carry_box_runs):
    """On an arm that is not S-R-S no arm angle is recorded: the claims needing it are not available, naming the
    metric, and judge nothing (``reproduce --robot`` crashed with a KeyError here)."""
    from dataclasses import replace

    from dualarm.reproduce.claims import consistency_claims

    angle = "ik.rep_arm_angle_deviation_max_rad"
    runs = [replace(r, metrics={k: v for k, v in r.metrics.items() if k != angle}) for r in carry_box_runs]
    claims = consistency_claims("carry_box", runs)
    assert len(claims) == 2
    for claim in claims:
        assert claim.ours == f"not available: {angle} was not computed: the arm angle needs an S-R-S arm"
        assert claim.agrees is None
