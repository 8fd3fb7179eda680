"""The papers' claims, each set against ours as read back from a reproduction's recordings.

Every "ours" figure here is computed from files the reproduction wrote: run directories through
:func:`dualarm.record.readback.read_run` (their topics and ``metrics.json``), ``table_i.json``
and ``plan_trials.csv``. The papers' figures are constants quoted from their text.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.record.readback import RunData, read_run
from dualarm.report.run_report import excursions, hand_errors, limit_excursions
from dualarm.reproduce.experiments import TABLE_I_SOLUTION_1
from dualarm.study.planning import PAPER_PLANNING_TIME_S

#: Numbers below this are taken as zero (rounding of the recorded doubles) [rad, rad/s, m].
ZERO = 1e-9
#: Joint or arm-angle change between repetitions that counts as "the motion changes" [rad].
CHANGES_RAD = 0.01


@dataclass(frozen=True)
class Claim:
    """One claim of a paper against ours.

    Attributes:
        paper: the paper (TV-GDD, MC-Inverse, Li & Liang).
        where: its figure, table or section.
        claim: what it says.
        theirs: its figure, as printed.
        ours: ours, with the unit.
        comparison: ours against theirs (a ratio, a difference), or what decides the verdict.
        agrees: whether ours bears the claim out (None where there is nothing to judge).
        part: the reproduction part that measured it (:data:`dualarm.reproduce.experiments.PARTS`).
        verdict: the verdicts of the runs it reads (``method: status`` and a violated run's first
            violation), "" where it reads none.
        contradicted: a run the claim needs ``complete`` (MC-Inverse's, TV-GDD's executed ball game,
            the carried box, the planner's executed plan) is not: the claim cannot stand on it.
    """

    paper: str
    where: str
    claim: str
    theirs: str
    ours: str
    comparison: str
    agrees: bool | None
    part: str
    verdict: str = ""
    contradicted: bool = False


def run_verdict(label: str, run: RunData) -> str:
    """``label: status``, with a violated or failed run's first violation or error and how many more."""
    violations = run.violations
    first = run.error or (violations[0] if violations else "")
    more = f"; {len(violations) - 1} more" if len(violations) > 1 else ""
    return f"{label}: {run.status}" + (f" ({first}{more})" if first else "")


def _needing(claim: Claim, label: str, run: RunData | None) -> Claim:
    """``claim`` carrying ``run``'s verdict, contradicted (and not agreeing) unless that run is complete."""
    if run is None:
        return claim
    contradicted = run.status != "complete"
    return replace(
        claim,
        verdict=run_verdict(label, run),
        contradicted=contradicted,
        agrees=False if contradicted else claim.agrees,
    )


def _run_failed(labels: str) -> str:
    """The "ours" of a claim whose runs ``labels`` failed."""
    return f"not available: the {labels} run failed (see its manifest)"


def _failed_run(paper: str, where: str, claim: str, theirs: str, part: str, label: str, run: RunData) -> Claim:
    """The one claim left of a part whose run failed: that the run completes, contradicted, with its error."""
    return _needing(Claim(paper, where, claim, theirs, _run_failed(label), "", None, part), label, run)


def _g(value: float, unit: str = "", digits: int = 3) -> str:
    return f"{value:.{digits}g}{' ' + unit if unit else ''}"


def _largest(table: pd.DataFrame, unit: str) -> tuple[float, str]:
    """(largest excursion, its description) of an excursion table; (0, "none") when empty."""
    if table.empty:
        return 0.0, "none"
    row = table.iloc[table["max_outside"].argmax()]
    return float(
        row["max_outside"]
    ), f"{row['max_outside']:.3g} {unit} ({row['joint']}, first at {row['t_first_out']:.2f} s)"


def _unexpected_contact_steps(run: RunData) -> int:
    executed = run["/execute/sample"]
    return int(((executed["self_contacts"] + executed["environment_contacts"]) > 0).sum())


def pinv_claims(pinv: RunData) -> list[Claim]:
    """Zhang, Kong, Niu, section 4: the ball game with the pseudoinverse (Figs 3-4)."""
    claims = []
    for kind, unit, where, text in (
        ("position", "rad", "Fig. 3", "pinv's joints leave the expected bounds θ_new±"),
        ("velocity", "rad/s", "Fig. 4", "pinv's joint velocities exceed their bounds ζ_new±"),
    ):
        value, ours = _largest(excursions(pinv["/ik/sample"], pinv["/ik/bounds"], kind), unit)
        claims.append(
            Claim(
                "TV-GDD",
                where,
                text,
                "yes (drawn, no figure given)",
                ours,
                "outside by more than 0" if value > ZERO else "stays inside",
                value > ZERO,
                "ball-game-pinv",
                run_verdict("pinv", pinv),
            )
        )
    return claims


def tvgdd_claims(tvgdd: RunData) -> list[Claim]:
    """Zhang, Kong, Niu, section 4: the ball game with TV-GDD (Figs 5-8, the computing times).

    A failed run gives one claim, contradicted: that the motion runs.
    """
    if tvgdd.status == "failed":
        return [
            _failed_run(
                "TV-GDD",
                "Figs 5-8",
                "TV-GDD generates the ball game and it runs on the robot",
                "done on the physical robot",
                "ball-game-tvgdd",
                "tvgdd",
                tvgdd,
            )
        ]
    claims = []
    sample, bounds = tvgdd["/ik/sample"], tvgdd["/ik/bounds"]
    value, ours = _largest(excursions(sample, bounds, "position"), "rad")
    claims.append(
        Claim(
            "TV-GDD",
            "Fig. 5",
            "TV-GDD's joints stay within θ_new±",
            "0 (drawn)",
            ours,
            "",
            value <= ZERO,
            "ball-game-tvgdd",
        )
    )
    velocity, ours = _largest(excursions(sample, bounds, "velocity"), "rad/s")
    physical, ours_physical = _largest(
        pd.concat([limit_excursions(sample, tvgdd["/ik/limits"], k) for k in ("position", "velocity")]), "rad or rad/s"
    )
    claims.append(
        Claim(
            "TV-GDD",
            "Fig. 6",
            "TV-GDD's velocities stay within ζ_new± and no joint leaves its physical limits",
            "0 (drawn)",
            f"ζ±: {ours}; physical: {ours_physical}",
            "",
            max(velocity, physical) <= ZERO,
            "ball-game-tvgdd",
        )
    )
    t = bounds["t"].to_numpy()
    closed = {}
    for column in bounds.columns:
        if column.startswith("theta_lower."):
            joint = column.split(".", 1)[1]
            width = bounds[f"theta_upper.{joint}"].to_numpy() - bounds[column].to_numpy()
            if width[0] > ZERO and width[-1] <= 1e-6 * width[0]:
                closed[joint] = float(t[np.argmax(width <= 0.01 * width[0])])
    if closed:
        latest = max(closed.values())
        claims.append(
            Claim(
                "TV-GDD",
                "Fig. 5",
                "the gesture joints' bounds (its joints 6, 7, 13, 14) close after about 5 s",
                "≈ 5 s",
                f"{latest:.2f} s, 99 % closed ({', '.join(closed)})",
                f"{latest - 5.0:+.2f} s",
                abs(latest - 5.0) <= 1.0,
                "ball-game-tvgdd",
            )
        )
    errors = hand_errors(sample)
    for name, theirs, ours_value in (
        ("largest hand position error (MAE)", 2.1832e-5, float(errors.to_numpy().max())),
        ("mean hand position error (AAE) of each hand, below", 6.2e-6, float(errors.mean().max())),
        ("RMS hand position error of each hand, below", 8.41e-6, float(np.sqrt((errors**2).mean()).max())),
    ):
        claims.append(
            Claim(
                "TV-GDD",
                "Fig. 8",
                name,
                _g(theirs, "m", 5),
                _g(ours_value, "m") + (" (the larger hand)" if "each" in name else ""),
                f"ours / paper = {ours_value / theirs:.2f}",
                ours_value <= theirs,
                "ball-game-tvgdd",
            )
        )
    solve = sample["solve_time_s"].to_numpy()
    for name, theirs, ours_value in (
        ("T_ave, computing time per control step", 1e-3, float(solve.mean())),
        ("T_sum, computing time of the whole task", 1.12, float(solve.sum())),
    ):
        claims.append(
            Claim(
                "TV-GDD",
                "section 4",
                name,
                _g(theirs, "s", 5),
                _g(ours_value, "s"),
                f"paper / ours = {theirs / ours_value:.0f}x",
                ours_value <= theirs,
                "ball-game-tvgdd",
            )
        )
    executed = tvgdd["/execute/sample"]
    tracking = float(hand_errors(executed).to_numpy().max())
    contacts = _unexpected_contact_steps(tvgdd)
    claims = [replace(c, verdict=run_verdict("tvgdd", tvgdd)) for c in claims]
    executed_claim = Claim(
        "TV-GDD",
        "Fig. 7",
        "the motion runs on the robot and keeps the hand gesture",
        "done on the physical robot",
        f"executed in PyBullet: tracking error {tracking * 1e6:.2f} µm, {contacts} steps with unexpected contacts",
        "",
        contacts == 0 and tracking < 1e-3,
        "ball-game-tvgdd",
    )
    return [*claims, _needing(executed_claim, "tvgdd", tvgdd)]


#: The paper's Table I, solutions 1-4 (columns), joints 1-7 (rows) [rad].
PAPER_TABLE_I = np.array(
    [
        TABLE_I_SOLUTION_1,
        (-1.29361, -0.21282, 1.05878, -1.94261, 0.54827, 1.29769, 1.38904),
        (-1.84799, 0.21282, -2.08281, -1.94261, -2.59332, -1.29769, 1.75256),
        (1.29361, -0.21282, 1.05878, -1.94261, -2.59332, -1.29769, 1.75256),
    ]
)
#: Half a unit of the table's last printed decimal, plus rounding of the analogue's pose [rad].
TABLE_DECIMALS_RAD = 1e-5


def table_i_claims(table: Mapping) -> list[Claim]:
    """Zou, Min, Xu, Table I and Fig. 6, against ``table_i.json``."""
    candidates = table["candidates"]
    q = np.array([c["q"] for c in candidates])
    valid = np.array([c["valid"] for c in candidates])
    psi = np.array([c["arm_angle_rad"] for c in candidates])
    claims = [
        Claim(
            "MC-Inverse",
            "Table I",
            "one pose and arm angle give 8 candidate solutions",
            "8",
            str(len(candidates)),
            "",
            len(candidates) == 8,
            "table-i",
        )
    ]
    elbow_sign = np.sign(PAPER_TABLE_I[0, 3])
    paper_sign = valid & (np.sign(q[:, 3]) == elbow_sign)
    claims.append(
        Claim(
            "MC-Inverse",
            "Table I",
            "4 of them are valid",
            "4",
            f"{valid.sum()} ({paper_sign.sum()} with the paper's elbow sign θ4 < 0)",
            "this elbow bends both ways within its limits, HR2's one way",
            int(valid.sum()) == 4,
            "table-i",
        )
    )
    spread = float(np.abs(psi[valid] - table["arm_angle"]).max()) if valid.any() else np.nan
    claims.append(
        Claim(
            "MC-Inverse",
            "Table I, Fig. 6",
            "the valid solutions have the arm angle asked for",
            "identical",
            f"largest |ψ(q) − ψ| = {spread:.2g} rad",
            "",
            spread <= ZERO,
            "table-i",
        )
    )
    elbows = q[paper_sign, 3]
    elbow_spread = float(np.ptp(elbows)) if len(elbows) else np.nan
    claims.append(
        Claim(
            "MC-Inverse",
            "Table I",
            "the valid solutions share θ4 and differ only at the shoulder and the wrist",
            "θ4 = −1.94261 in all 4",
            f"θ4 = {elbows[0]:.5f} in all {len(elbows)} (spread {elbow_spread:.2g} rad)" if len(elbows) else "none",
            f"{elbows[0] - PAPER_TABLE_I[0, 3]:+.1g} rad" if len(elbows) else "",
            elbow_spread <= ZERO,
            "table-i",
        )
    )
    equal, signed, unmatched = 0, [], []
    for j, column in enumerate(PAPER_TABLE_I):
        best = np.argmin([np.sum(np.abs(column - row) > TABLE_DECIMALS_RAD) for row in q])
        for i, (theirs, ours) in enumerate(zip(column, q[best], strict=True)):
            if abs(theirs - ours) <= TABLE_DECIMALS_RAD:
                equal += 1
            elif abs(theirs + ours) <= TABLE_DECIMALS_RAD:
                signed.append(f"solution {j + 1} θ{i + 1}")
            else:
                unmatched.append(f"solution {j + 1} θ{i + 1}")
    claims.append(
        Claim(
            "MC-Inverse",
            "Table I",
            "the joint values of the 4 solutions",
            "28 values",
            f"{equal} of 28 equal to 5 decimals; {len(signed)} equal but "
            f"for the sign ({', '.join(signed)}); {len(unmatched)} others",
            "the sign differences break the table's own ZYZ pattern (θ1 "
            "+ π, θ7 + π between paired solutions), see docs/papers.md",
            not unmatched,
            "table-i",
        )
    )
    return claims


def _by_method(runs: list[RunData]) -> dict[str, RunData]:
    """Method -> the finished (complete or violated) consistency runs (IK only) of one task."""
    return {
        str(r.setting("ik", "method")): r
        for r in runs
        if r.status in ("complete", "violated") and "retime" not in r.stages
    }


#: Why a consistency metric a claim needs may be missing from a run's metrics (on a robot other than the humanoid).
UNCOMPUTED = {
    "ik.rep_joint_deviation_max_rad": "was not computed: no sample was solved in two repetitions",
    "ik.rep_arm_angle_deviation_max_rad": "was not computed: the arm angle needs an S-R-S arm",
}


def _deviation(metrics: Mapping[str, float]) -> str:
    return (
        f"Δq {metrics['ik.rep_joint_deviation_max_rad']:.2g} rad, "
        f"Δψ {metrics['ik.rep_arm_angle_deviation_max_rad']:.2g} rad"
    )


def consistency_claims(task: str, runs: list[RunData]) -> list[Claim]:
    """Zou, Min, Xu, V.B-V.D: each method's largest change between repetitions.

    Rep 0 is the reference; ``ik.rep_*`` of each run's metrics.

    A claim about a method whose run failed says so and is not judged.
    """
    finished = _by_method(runs)
    m = {method: run.metrics for method, run in finished.items()}
    where = {"triangle": "V.B, Figs 9-10", "circle": "V.C, Figs 12-13", "carry_box": "V.D, Fig. 16"}[task]
    part = {"carry_box": "carry-box"}.get(task, task)

    def dq(method: str) -> float:  # a KeyError naming the metric when the run could not compute it (UNCOMPUTED)
        return m[method]["ik.rep_joint_deviation_max_rad"]

    def dpsi(method: str) -> float:
        return m[method]["ik.rep_arm_angle_deviation_max_rad"]

    def claim(
        text: str,
        theirs: str,
        methods: tuple[str, ...],
        ours: Callable[[], str],
        agrees: Callable[[], bool],
        comparison: Callable[[], str] = lambda: "",
    ) -> Claim:
        failed = [method for method in methods if method not in m]
        if failed:
            made = Claim(
                "MC-Inverse",
                where,
                text,
                theirs,
                _run_failed(", ".join(failed)),
                "",
                None,
                part,
            )
            return (
                _needing(made, "mc-inverse", next((r for r in runs if r.setting("ik", "method") == "mc-inverse"), None))
                if "mc-inverse" in failed
                else made
            )
        try:
            made = Claim(
                "MC-Inverse",
                where,
                text,
                theirs,
                ours(),
                comparison(),
                agrees(),
                part,
                "; ".join(run_verdict(method, finished[method]) for method in methods),
            )
        except KeyError as missing:  # a metric the runs could not compute on this robot
            metric = str(missing.args[0])
            why = UNCOMPUTED.get(metric, "not among the runs' metrics")
            return Claim("MC-Inverse", where, text, theirs, f"not available: {metric} {why}", "", None, part)
        return _needing(made, "mc-inverse", finished["mc-inverse"]) if methods == ("mc-inverse",) else made

    claims = [
        claim(
            f"{task}: MC-Inverse repeats its joints and arm angles",
            "identical (drawn)",
            ("mc-inverse",),
            lambda: _deviation(m["mc-inverse"]),
            lambda: max(dq("mc-inverse"), dpsi("mc-inverse")) <= ZERO,
        )
    ]
    if task == "triangle":
        claims += [
            claim(
                "triangle: TRAC-IK's joints change between repetitions",
                "change (drawn)",
                ("trac-ik",),
                lambda: _deviation(m["trac-ik"]),
                lambda: dq("trac-ik") > CHANGES_RAD,
                lambda: f"changes by more than {CHANGES_RAD} rad" if dq("trac-ik") > CHANGES_RAD else "no change",
            ),
            claim(
                "triangle: TRAC-IK fails the 4th and 5th repetitions (joint limit)",
                "2 failed",
                ("trac-ik",),
                lambda: f"{m['trac-ik']['ik.failed_reps']:.0f} failed",
                lambda: m["trac-ik"]["ik.failed_reps"] >= 1,
            ),
            claim(
                "triangle: ikfast's arm motion changes, and its joints jump",
                "change, jumps (drawn)",
                ("ikfast-style", "mc-inverse"),
                lambda: (
                    f"{_deviation(m['ikfast-style'])}; largest step "
                    f"{m['ikfast-style']['ik.max_joint_step_rad']:.2g} rad"
                ),
                lambda: (
                    dq("ikfast-style") > CHANGES_RAD
                    and m["ikfast-style"]["ik.max_joint_step_rad"] > 10 * m["mc-inverse"]["ik.max_joint_step_rad"]
                ),
                lambda: f"MC-Inverse's largest step {m['mc-inverse']['ik.max_joint_step_rad']:.2g} rad",
            ),
        ]
    if task == "circle":
        claims += [
            claim(
                "circle: TRAC-IK's joints change every circle",
                "change (drawn)",
                ("trac-ik",),
                lambda: _deviation(m["trac-ik"]),
                lambda: dq("trac-ik") > CHANGES_RAD,
            ),
            claim(
                "circle: ikfast is more consistent than TRAC-IK, but its arm angle still changes",
                "changes on the 3rd circle",
                ("ikfast-style", "trac-ik"),
                lambda: f"ikfast-style Δψ {dpsi('ikfast-style'):.2g} rad, TRAC-IK Δψ {dpsi('trac-ik'):.2g} rad",
                lambda: CHANGES_RAD < dpsi("ikfast-style") < dpsi("trac-ik"),
            ),
        ]
    if task == "carry_box":
        claims.append(
            claim(
                "box: TRAC-IK's and ikfast's arm angles change significantly, ikfast's less",
                "change (drawn)",
                ("trac-ik", "ikfast-style"),
                lambda: f"TRAC-IK {_deviation(m['trac-ik'])}; ikfast-style {_deviation(m['ikfast-style'])}",
                lambda: CHANGES_RAD < dpsi("ikfast-style") < dpsi("trac-ik"),
            )
        )
    return claims


def carry_box_claims(executed: RunData) -> list[Claim]:
    """Zou, Min, Xu, eq (11) and Fig. 14: the box carried, executed.

    A failed run gives one claim, contradicted: that the box is carried.
    """
    if executed.status == "failed":
        return [
            _failed_run(
                "MC-Inverse",
                "eq (11), Fig. 14",
                "the two hands carry the box with MC-Inverse, executed",
                "done",
                "carry-box",
                "mc-inverse, executed",
                executed,
            )
        ]
    sample = executed["/execute/sample"]
    left = sample[[f"hand_position.left.{a}" for a in "xyz"]].to_numpy()
    right = sample[[f"hand_position.right.{a}" for a in "xyz"]].to_numpy()
    distance = np.linalg.norm(left - right, axis=1)
    drift = float(np.abs(distance - distance[0]).max())
    ratios = executed.metrics
    claims = [
        Claim(
            "MC-Inverse",
            "eq (11), Fig. 14",
            "the slave hand follows the master: no relative motion between the hands",
            "none",
            f"executed hands' distance varies by {drift * 1e3:.3f} mm",
            "",
            drift < 1e-3,
            "carry-box",
        ),
        Claim(
            "MC-Inverse",
            "section IV",
            "TOPP gives a time-optimal trajectory within the velocity and acceleration limits",
            "within (no figure)",
            f"retimed velocity / limit {ratios['retime.velocity_ratio_max']:.3f}, "
            f"acceleration / limit {ratios['retime.acceleration_ratio_max']:.3f}",
            "TOPP-RA at 90 % / 30 % of the limits",
            max(ratios["retime.velocity_ratio_max"], ratios["retime.acceleration_ratio_max"]) <= 1.0,
            "carry-box",
        ),
    ]
    return [_needing(c, "mc-inverse, executed", executed) for c in claims]


def plan_claims(trials: pd.DataFrame, run: RunData | None) -> list[Claim]:
    """Li & Liang, section 5: MCIKRRT on the bowl grasp (``plan_trials.csv``) and the first plan executed."""
    successes = trials[trials["success"]]
    claims = [
        Claim(
            "Li & Liang",
            "section 5, Fig. 1",
            "MCIKRRT finds a collision-free path for the dual-arm grasp",
            "found (one scene)",
            f"{len(successes)} of {len(trials)} trials",
            "",
            len(successes) > 0,
            "bowl-grasp",
        )
    ]
    if len(successes):
        mean = float(successes["planning_time_s"].mean())
        claims.append(
            Claim(
                "Li & Liang",
                "section 5",
                "average planning time",
                f"{PAPER_PLANNING_TIME_S * 1e3:.2f} ms (i7-3770)",
                f"{mean * 1e3:.1f} ms (median {successes['planning_time_s'].median() * 1e3:.1f} ms)",
                f"paper / ours = {PAPER_PLANNING_TIME_S / mean:.0f}x",
                mean <= PAPER_PLANNING_TIME_S,
                "bowl-grasp",
            )
        )
    if run is not None:
        contacts = _unexpected_contact_steps(run)
        claims.append(
            Claim(
                "Li & Liang",
                "section 5, Fig. 2",
                "the planned joint motion is collision-free",
                "yes",
                f"executed in PyBullet: {contacts} steps with unexpected contacts, tracking "
                f"error {run.metrics['execute.tracking_error_max_m'] * 1e6:.1f} µm",
                "",
                contacts == 0,
                "bowl-grasp",
            )
        )
        claims[-1] = _needing(claims[-1], "mcikrrt, executed", run)
    return claims


def all_claims(out: Path, parts: Mapping[str, Mapping]) -> list[Claim]:
    """Every claim whose part completed, read back from the reproduction in ``out``.

    ``parts``: part name -> its entry in parts.json.
    """

    def runs(name: str) -> list[RunData]:
        return [read_run(out / r) for r in parts[name]["outputs"].get("runs", [])]

    done = {name for name, p in parts.items() if p["status"] == "complete"}
    readers: list[tuple[set[str], Callable[[], list[Claim]]]] = [
        ({"ball-game-pinv"}, lambda: pinv_claims(runs("ball-game-pinv")[0])),
        ({"ball-game-tvgdd"}, lambda: tvgdd_claims(runs("ball-game-tvgdd")[0])),
        ({"table-i"}, lambda: table_i_claims(json.loads((out / parts["table-i"]["outputs"]["table"]).read_text()))),
        ({"triangle"}, lambda: consistency_claims("triangle", runs("triangle"))),
        ({"circle"}, lambda: consistency_claims("circle", runs("circle"))),
        (
            {"carry-box"},
            lambda: (
                consistency_claims("carry_box", runs("carry-box"))
                + carry_box_claims([r for r in runs("carry-box") if "execute" in r.stages][0])
            ),
        ),
        (
            {"bowl-grasp"},
            lambda: plan_claims(
                pd.read_csv(out / parts["bowl-grasp"]["outputs"]["table"]),
                runs("bowl-grasp")[0] if parts["bowl-grasp"]["outputs"].get("runs") else None,
            ),
        ),
    ]
    claims = []
    for needed, read in readers:
        if needed <= done:
            claims.extend(read())
    return claims
