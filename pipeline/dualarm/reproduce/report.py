"""``report.md`` of a reproduction: each paper claim against ours, the figures, the runs and times.

The time of each part. Written from the reproduction directory's files alone (so it can be rewritten
from a directory copied from another machine).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from dualarm.errors import RecordingError
from dualarm.record.readback import read_run
from dualarm.record.run_dir import write_whole
from dualarm.report import figures
from dualarm.report.run_report import write_report
from dualarm.reproduce.claims import PAPER_TABLE_I, Claim, all_claims, run_verdict
from dualarm.reproduce.experiments import BY_NAME, PARTS, ROBOT, command, robot_option
from dualarm.reproduce.runner import NOT_AVAILABLE, PARTS_FILE

#: The papers, in the order of the report.
PAPERS = {
    "TV-GDD": (
        "Zhang, Kong, Niu — *A Time-Varying-Constrained Motion Generation Scheme for Humanoid Robot Arms* "
        "(ball game, section 4)"
    ),
    "MC-Inverse": (
        "Zou, Min, Xu — *MC-Inverse: An Analytical Method for Consistent Motion of Anthropomorphic Dual-arm Robot* "
        "(section V)"
    ),
    "Li & Liang": (
        "Li, Liang — *Study on Humanoid Robot's Dual-arm Collision Avoidance Motion Planning Algorithm* (section 5)"
    ),
}
VERDICT = {True: "agrees", False: "**differs**", None: "—"}


def command_of(name: str, out: Path, parts: Mapping[str, Mapping], robot: Path = ROBOT) -> str:
    """The command that reproduces part ``name`` alone on the robot directory ``robot``.

    Table I's with the analogue's pose.
    """
    text = command(BY_NAME[name], robot)
    if name == "table-i" and parts.get(name, {}).get("status") == "complete":
        data = json.loads((out / parts[name]["outputs"]["table"]).read_text())
        text = text.format(pose=" ".join(str(v) for v in data["pose"]), psi=str(data["arm_angle"]))
    return text


def _robot(index: Mapping) -> Path:
    """The robot directory a reproduction ran on (the humanoid for one written before ``--robot``)."""
    return Path(index["robot"]["directory"]) if "robot" in index else ROBOT


def _claims_table(claims: list[Claim], out: Path, parts: Mapping[str, Mapping], robot: Path) -> list[str]:
    lines = [
        "| where | claim | paper | ours | ours against the paper | verdict | runs' verdicts | reproduce alone |",
        "|---|---|---|---|---|---|---|---|",
    ]
    cells = [
        (
            c.where,
            c.claim,
            c.theirs,
            c.ours,
            c.comparison,
            VERDICT[c.agrees],
            ("**contradicted:** " if c.contradicted else "") + c.verdict,
            f"`{command_of(c.part, out, parts, robot)}`",
        )
        for c in claims
    ]
    return lines + ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in cells]


def _table_i(out: Path, parts: Mapping[str, Mapping]) -> list[str]:
    data = json.loads((out / parts["table-i"]["outputs"]["table"]).read_text())
    lines = [
        "## Table I, ours and the paper's",
        "",
        "HR2's arm base frame and link lengths are not this robot's, so the paper's pose cannot "
        "be reused. The analogue puts this robot's left arm at the paper's solution 1 joints (its "
        "axes run z, y, z, y, z, y, z like HR2's) and asks MC-Inverse for the hand pose found "
        f"there, {data['pose']} (m, rad, in `{data['chain']['base']}`), at that configuration's "
        f"arm angle ψ = {data['arm_angle']:g} rad (the paper's 2.2 rad is in HR2's convention).",
        "",
        "| # | θ1 | θ2 | θ3 | θ4 | θ5 | θ6 | θ7 | ours | ψ(q) [rad] | FK error [m] |",
        "|---|" + "---:|" * 7 + "---|---:|---:|",
    ]
    lines += [
        f"| {i + 1} | "
        + " | ".join(f"{v:.5f}" for v in c["q"])
        + f" | {c['reason']} | {c['arm_angle_rad']:.5f} | {c['position_error_m']:.1e} |"
        for i, c in enumerate(data["candidates"])
    ]
    lines += [
        f"| paper {j + 1} | " + " | ".join(f"{v:.5f}" for v in column) + " | valid | | |"
        for j, column in enumerate(PAPER_TABLE_I)
    ]
    return lines + [""]


def _figures(out: Path, parts: Mapping[str, Mapping]) -> list[tuple[str, str]]:
    """(caption, path relative to ``out``) of the report's figures, made or found for the completed parts."""
    made = []
    done = {n for n, p in parts.items() if p["status"] == "complete"}
    for name, caption in (
        ("ball-game-pinv", "pinv (TV-GDD Figs 3-4)"),
        ("ball-game-tvgdd", "TV-GDD (Figs 5-6, 8; eq (19) profiles as Fig. 2)"),
    ):
        if name in done:
            directory = write_report(out / parts[name]["outputs"]["runs"][0], out / "figures" / name)
            for png, what in (
                ("joints_vs_bounds.png", "joint positions against θ_new±"),
                ("velocities_vs_bounds.png", "joint velocities against ζ_new±"),
                ("hand_errors.png", "hand position errors"),
                ("bound_profiles.png", "bound profiles of eq (19)"),
            ):
                if (directory / png).exists() and not (
                    name == "ball-game-pinv" and png in ("hand_errors.png", "bound_profiles.png")
                ):
                    made.append((f"Ball game, {caption}: {what}", str((directory / png).relative_to(out))))
    for name, task in (("triangle", "triangle"), ("circle", "circle"), ("carry-box", "carry_box")):
        if name in done:
            directory = out / Path(parts[name]["outputs"]["table"]).parent
            made += [
                (f"{task}: {png.stem.replace('_', ' ')} per repetition and method", str(png.relative_to(out)))
                for png in sorted(directory.glob("*.png"))
            ]
    if "bowl-grasp" in done:
        trials = pd.read_csv(out / parts["bowl-grasp"]["outputs"]["table"])
        times = trials.loc[trials["success"], "planning_time_s"].to_numpy() * 1e3
        if len(times):
            path = figures.histogram(
                times,
                "planning time [ms]",
                f"MCIKRRT on the bowl grasp: {len(times)} successful trials",
                out / "figures" / "planning_times.png",
                {f"ours, mean {times.mean():.0f} ms": float(times.mean())},
            )
            made.append(
                (
                    "Bowl grasp: MCIKRRT planning times (the paper's mean, 4210.88 ms, is off this scale)",
                    str(path.relative_to(out)),
                )
            )
    return made


def _why_absent(part: Mapping | None, robot: str) -> str:
    """Why a part has no claims: not run, not available on ``robot`` (and why), or failed (and why)."""
    if part is None:
        return "not run (see --only)"
    if part["status"] == NOT_AVAILABLE:
        return f"not available on {robot}: {part['error']}"
    return f"failed: {part['error']}"


def _index(out: Path) -> dict:
    try:
        return json.loads((out / PARTS_FILE).read_text())
    except (FileNotFoundError, json.JSONDecodeError) as exc:
        raise RecordingError(f"{out / PARTS_FILE}: not a reproduction's index ({exc})") from None


def reproduction_claims(out: str | Path) -> list[Claim]:
    """Every claim of the reproduction in ``out``, read back from its files.

    Raises:
        RecordingError: ``out`` holds no reproduction, or a recording it lists is unreadable.
    """
    out = Path(out)
    return all_claims(out, {p["name"]: p for p in _index(out)["parts"]})


def write_reproduction_report(out: str | Path, claims: list[Claim] | None = None) -> Path:
    """Write ``out/report.md`` from ``out/parts.json`` and the recordings it lists; returns it.

    ``claims``: :func:`reproduction_claims`, read when not given.

    Raises:
        RecordingError: ``out`` holds no reproduction, or a recording it lists is unreadable.
    """
    out = Path(out)
    index = _index(out)
    parts = {p["name"]: p for p in index["parts"]}
    (out / "figures").mkdir(exist_ok=True)
    claims = all_claims(out, parts) if claims is None else claims
    judged = [c for c in claims if c.agrees is not None]
    contradicted = [c for c in claims if c.contradicted]
    robot = _robot(index)
    name = index.get("robot", {}).get("name", "humanoid")
    lines = [
        "# dualarm: the three papers reproduced" + (f" on {name}" if robot_option(robot) else ""),
        "",
        *(
            []
            if not robot_option(robot)
            else [
                f"Robot: `{name}` ({robot}); the tasks transfer to it as "
                "tasks/README.md describes (frame, scale, `[transfer]`).",
                "",
            ]
        ),
        f"{sum(bool(c.agrees) for c in judged)} of {len(judged)} claims agree"
        + (
            f"; {len(contradicted)} rest on a run whose verdict is not complete (marked **contradicted**)"
            if contradicted
            else ""
        )
        + '. Every figure under "ours" is read back from the recordings in this directory; '
        "the papers' figures are quoted from their text. "
        f"The parts ran {index['jobs']} at a time on a "
        f"{index['cpu_count']}-core machine in {index['wall_time_s']:.0f} s"
        + (
            ", so computing times were measured with another part running "
            "(`--jobs 1` runs one part at a time; `dualarm bench` measures speed as ratios)."
            if index["jobs"] > 1
            else "."
        ),
        "",
    ]
    missing = [p for p in PARTS if p.name not in parts or parts[p.name]["status"] != "complete"]
    for paper, title in PAPERS.items():
        mine = [c for c in claims if c.paper == paper]
        lines += [f"## {paper}", "", title, ""]
        lines += _claims_table(mine, out, parts, robot) if mine else []
        absent = [p for p in missing if p.paper == paper]
        lines += ["", *[f"- {p.title} (`{p.name}`): {_why_absent(parts.get(p.name), name)}" for p in absent], ""]
    if parts.get("table-i", {}).get("status") == "complete":
        lines += _table_i(out, parts)
    lines += ["## Figures", ""] + [
        f"{caption}:\n\n![{Path(path).stem}]({path})\n" for caption, path in _figures(out, parts)
    ]
    lines += ["## Runs", "", "| part | run | verdict | stages |", "|---|---|---|---|"]
    for p in index["parts"]:
        for run in p["outputs"].get("runs", []):
            try:
                recorded = read_run(out / run)
            except RecordingError as exc:
                lines.append(f"| {p['name']} | {run} | unreadable: {exc} | |")
                continue
            verdict = run_verdict(
                str(recorded.setting("ik", "method") or recorded.setting("plan", "method") or "run"), recorded
            ).replace("|", "\\|")
            lines.append(f"| {p['name']} | [{run}]({run}) | {verdict} | {', '.join(recorded.stages)} |")
    lines += ["", "## Time of each part", "", "| part | what | status | time [s] |", "|---|---|---|---:|"]
    lines += [
        f"| {p['name']} | {BY_NAME[p['name']].title} | {p['status']} | {p['seconds']:.1f} |" for p in index["parts"]
    ]
    lines += [f"| all | {index['jobs']} at a time | | {index['wall_time_s']:.1f} |", ""]
    return write_whole(out / "report.md", "\n".join(lines))
