"""``dualarm analyze``: a robot's repeated motion from a ROS 2 bag, judged as ``consistency`` does.

The MC-Inverse paper's question on measured data: does the robot put its joints at the same place every time its
hands pass the same place? The bag's ``sensor_msgs/msg/JointState`` messages
(:func:`dualarm.record.ros2.read_joint_states`) are

1. **cleaned of noise, which is estimated first.** A joint's noise sigma is the spread of its positions about a
   local cubic (a Savitzky-Golay fit over :data:`SMOOTH_WINDOW_S`): the median absolute residual / 0.6745, divided
   by sqrt(1 - h0), h0 the fit's own weight on the sample. The positions compared are that fit's. Samples are
   taken in the bag's order, at the least-squares slope of their stamps against their index: a driver's stamp
   jitter moves no position (it stamps samples taken at a fixed rate), and the median step would be 1 % off
   under 1 ms of jitter;
2. **cut into repetitions** where the hands pass the first repetition's start pose (the task's start pose, or the
   hands' pose at the first message), by the robot's forward kinematics: each stretch of samples within
   :data:`START_SHARE` of the hands' largest excursion from it (hysteresis: it ends beyond twice that) is a
   pass, cut at its nearest sample. ``--period`` cuts every ``period`` seconds instead;
3. **compared at the same place**, not at the same time (a robot's repetitions need not take the same time): each
   sample of a later repetition is matched to the point of the first repetition where the hands are nearest, on the
   segment between two of its samples, and the joints (and arm angles, eq (1) of MC-Inverse) are compared there;
4. **judged beyond the noise.** The noise floor is the largest deviation the same comparison finds between two
   copies of the first repetition's fitted path, each with independent noise of the estimated sigma and fitted
   again (:data:`NOISE_DRAWS` pairs, seeded): what noise of that level alone shows, the error of matching the
   place included. The motion is ``inconsistent`` when the largest joint deviation exceeds the threshold (the
   study's 0.01 rad by default) plus that floor; deviations within the floor are reported as noise. A first
   repetition that passes one hand place with different joints (a self-motion) raises the floor: it is reported.

Velocity, acceleration and jerk are the derivatives of a local cubic over :data:`DERIVATIVE_WINDOW_S`, each with its
own noise (sigma times the norm of the fit's weights); a limit counts as exceeded only when a ratio exceeds 1 +
1e-6 by more than noise reaches over all the estimates with probability :data:`FALSE_ALARM`, as does a position
beyond a position limit. With a task, the hands' distance to its reference path (nearest point, in the task's
frame) is reported too.

Writes ``analysis.csv`` (a row of the metrics below), ``repetitions.csv``, ``analysis.md`` and the figures
``dualarm consistency`` draws (joints and arm angles per repetition).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.errors import DualarmError, RecordingError, excerpt
from dualarm.record.run_dir import claim_output_dir, write_whole
from dualarm.report import figures

#: Window of the local cubic the compared positions are taken from, and the noise estimated about [s].
SMOOTH_WINDOW_S = 0.021
#: Window of the local cubic whose derivatives are compared with the velocity, acceleration and jerk limits [s].
DERIVATIVE_WINDOW_S = 0.05
#: Probability that noise alone exceeds the noise floor somewhere over all the values compared.
FALSE_ALARM = 1e-3
#: A pass of the start pose: within this share of the hands' largest excursion from it (and at least START_MIN_M).
START_SHARE = 0.05
START_MIN_M = 1e-3
#: Weight of a hand's rotation [m per rad] beside its position in the distance to the start pose.
ROTATION_WEIGHT_M = 0.1
#: A limit is exceeded when its ratio, less what noise alone reaches over the estimates with probability FALSE_ALARM
#: (a normal quantile times its noise), is above 1 + LIMIT_SLACK.
LIMIT_SLACK = 1e-6
#: The joint deviation above which repetitions are inconsistent by default [rad] (a study's default).
THRESHOLD_RAD = 0.01
#: Pairs of noisy copies of the first repetition that the noise floor is the largest deviation of, and their seed.
NOISE_DRAWS = 4
NOISE_SEED = 0
#: Fewest samples a repetition must hold.
MIN_REP_SAMPLES = 10
#: What a limit is called in the table.
LIMIT_KINDS = ("velocity", "acceleration", "jerk")


@dataclass(frozen=True)
class Analysis:
    """What :func:`analyze_bag` wrote.

    Attributes:
        metrics: the row of ``analysis.csv``: ``verdict`` (consistent or inconsistent), ``repetitions``,
            ``rep_joint_deviation_max_rad`` (``rep_arm_angle_deviation_max_rad`` on arms that have one),
            ``noise_rad`` (the largest joint's sigma), ``noise_floor_rad``, ``rep_beyond_noise_max_rad`` (the
            deviation less the floor, at least 0), ``rep_hand_deviation_max_m`` (how far a later repetition's hands
            pass from the first's path), ``<kind>_ratio_max`` and ``_noise`` for each limit, ``position_beyond_rad``,
            ``hand_path_deviation_max_m`` with a task, ``samples``, ``period_s``, ``threshold_rad``.
        repetitions: a row per repetition: ``rep``, ``start_s``, ``end_s``, ``samples``, ``joint_deviation_max_rad``.
        violations: the limits exceeded beyond their noise, a line each.
        directory: where the files are.
        files: the files written.
    """

    metrics: dict[str, object]
    repetitions: pd.DataFrame
    violations: tuple[str, ...]
    directory: Path
    files: tuple[Path, ...]

    @property
    def consistent(self) -> bool:
        """Whether the repetitions repeat within the threshold plus the noise floor."""
        return self.metrics["verdict"] == "consistent"


def analyze_bag(
    bag: str | Path,
    robot: str | Path,
    out_dir: str | Path,
    task: str | Path | None = None,
    repetitions: int | None = None,
    period_s: float | None = None,
    topic: str = "/joint_states",
    rename: dict[str, str] | None = None,
    threshold_rad: float = THRESHOLD_RAD,
) -> Analysis:
    """Analyse the joint states of ``bag`` on ``robot`` (a robot directory or shipped name).

    ``repetitions``: how many the cut must find (refused otherwise); ``period_s``: cut by time instead.

    Raises:
        DualarmError: a robot, task or bag that cannot be read, a topic or joints the bag lacks, repetitions that
            cannot be cut, or arguments out of range; before anything is written.
    """
    from scipy.signal import savgol_coeffs, savgol_filter

    from dualarm.ik.metrics import joint_arm_angles
    from dualarm.model.robot import load_robot
    from dualarm.record.ros2 import read_joint_states

    if period_s is not None and not (np.isfinite(period_s) and period_s > 0):
        raise DualarmError(f"--period must be a positive number of seconds, not {period_s}")
    if not (np.isfinite(threshold_rad) and threshold_rad > 0):
        raise DualarmError(f"--threshold must be a positive angle in rad, not {threshold_rad}")
    loaded = _task(task, robot) if task is not None else None
    model = loaded.robot if loaded is not None else load_robot(robot)
    hands = loaded.spec.hands if loaded is not None else model.hands
    reference = _reference(loaded) if loaded is not None else None
    frame = reference.frame_in(model) if reference is not None else model.urdf.root
    chains = {hand: model.chain_between(frame, model.hand_chain(hand).tip) for hand in hands}
    wanted = tuple(dict.fromkeys(n for c in chains.values() for n in c.joint_names))
    states = read_joint_states(Path(bag), wanted, topic, rename)
    present = ~np.isnan(states.q_rad).all(axis=0)
    arm = {hand: set(model.hand_chain(hand).joint_names) for hand in hands}
    hands = tuple(h for h in hands if all(present[wanted.index(n)] for n in arm[h]))
    if not hands:
        missing = [n for n in wanted if not present[wanted.index(n)]]
        raise RecordingError(
            f"{excerpt(bag)}: {topic} lacks every hand's arm joints ({excerpt(', '.join(missing), 200)}); "
            "map names with --joint-map BAG_NAME=URDF_NAME"
        )
    held = loaded.initial_q if loaded is not None else {}
    q = np.where(np.isnan(states.q_rad), [held.get(n, 0.0) for n in wanted], states.q_rad)
    names = tuple(n for n in wanted if any(n in arm[h] for h in hands))
    columns = [wanted.index(n) for n in names]
    keep = ~np.isnan(states.q_rad[:, columns]).any(axis=1)  # messages of another publisher (a gripper) left out
    q, t = q[keep], states.t_s[keep]
    if len(t) < 3 * MIN_REP_SAMPLES:
        raise RecordingError(f"{excerpt(bag)}: {len(t)} samples of the arms' joints on {topic}; too few to analyse")
    dt = float(np.polyfit(np.arange(len(t)), t, 1)[0])  # the median step is off by ~1 % under 1 ms of jitter
    if not dt > 0:
        raise RecordingError(f"{excerpt(bag)}: the stamps on {topic} do not increase (mean step {dt} s)")

    window = _window(SMOOTH_WINDOW_S, dt)
    smooth = savgol_filter(q, window, 3, axis=0)
    sigma = _noise(q, smooth, float(savgol_coeffs(window, 3)[window // 2]))
    vertical = _vertical(loaded)

    def seen(q_fit: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The hands' poses and arm angles at fitted positions ``q_fit`` (every column of ``wanted``)."""
        poses = {
            h: _poses(c, q_fit[:, [wanted.index(n) for n in c.joint_names]]) for h, c in chains.items() if h in hands
        }
        return q_fit[:, columns], poses, joint_arm_angles(model, hands, wanted, q_fit, vertical)

    joints, poses, angles = seen(smooth)
    if period_s is not None:
        cuts = np.searchsorted(t, t[0] + period_s * np.arange(int((t[-1] - t[0]) / period_s + 1e-9) + 1))
    else:
        cuts = _passes(poses, _start_poses(reference, hands, poses))
    cuts = np.asarray(cuts)
    if len(cuts) < 3 or (np.diff(cuts) < MIN_REP_SAMPLES).any():
        how = f"every {period_s} s" if period_s is not None else "where the hands pass the start pose"
        raise RecordingError(
            f"{excerpt(bag)}: cutting {len(t)} samples ({t[-1] - t[0]:.3f} s) {how} gives "
            f"{max(len(cuts) - 1, 0)} repetition(s)"
            + (f", the shortest of {np.diff(cuts).min()} samples" if len(cuts) > 1 else "")
            + f"; at least 2 of at least {MIN_REP_SAMPLES} samples are needed"
            + ("" if period_s is not None else " (give --task for its start pose, or --period)")
        )
    if repetitions is not None and len(cuts) - 1 != repetitions:
        raise RecordingError(
            f"{excerpt(bag)}: found {len(cuts) - 1} repetitions where the hands pass the start pose, not {repetitions} "
            f"(starting at {', '.join(f'{t[c] - t[0]:.2f}' for c in cuts[:-1][:12])} s from the first sample)"
        )
    rep = np.full(len(t), -1)
    for r, (start, end) in enumerate(zip(cuts[:-1], cuts[1:], strict=True)):
        rep[start:end] = r
    first, later = np.arange(cuts[0], cuts[1]), np.arange(cuts[1], cuts[-1])
    deviation, angle_deviation, place_m = _compare(*(_take((joints, poses, angles), k) for k in (first, later)))
    # The noise floor: the same comparison between two copies of the first repetition's fitted path, each with
    # independent noise of the estimated sigma, fitted again (NOISE_DRAWS pairs; seeded).
    rng = np.random.default_rng(NOISE_SEED)
    floor, angle_floor = 0.0, 0.0
    for _ in range(NOISE_DRAWS):
        pair = [
            seen(savgol_filter(smooth[first] + rng.normal(0.0, sigma, (len(first), len(wanted))), window, 3, axis=0))
            for _ in range(2)
        ]
        noise_q, noise_psi, _ = _compare(*pair)
        floor, angle_floor = max(floor, float(noise_q.max())), max(angle_floor, float(noise_psi.max(initial=0.0)))
    worst = float(deviation.max())
    metrics: dict[str, object] = {
        "repetitions": len(cuts) - 1,
        "rep_joint_deviation_max_rad": worst,
        "noise_rad": float(sigma[columns].max()),
        "noise_floor_rad": floor,
        "rep_beyond_noise_max_rad": max(worst - floor, 0.0),
        "rep_hand_deviation_max_m": float(place_m.max()),
    }
    if angles:
        metrics["rep_arm_angle_deviation_max_rad"] = float(angle_deviation.max())
        metrics["arm_angle_noise_floor_rad"] = angle_floor
    violations = _limits(model, names, q[:, columns], sigma[columns], dt, metrics)
    if reference is not None:
        metrics["hand_path_deviation_max_m"] = _path_deviation(reference, poses)
    inconsistent = worst > threshold_rad + floor
    metrics = {
        "verdict": "inconsistent" if inconsistent else "consistent",
        **metrics,
        "samples": len(t),
        "period_s": dt,
        "threshold_rad": threshold_rad,
    }
    per_rep = pd.DataFrame(
        {
            "rep": np.arange(len(cuts) - 1),
            "start_s": t[cuts[:-1]] - t[0],
            "end_s": t[cuts[1:] - 1] - t[0],
            "samples": np.diff(cuts),
            "joint_deviation_max_rad": [0.0]
            + [float(deviation[rep[later] == r].max()) for r in range(1, len(cuts) - 1)],
        }
    )
    out = Path(out_dir)
    _claim = claim_output_dir(out, "analysis")
    sample = pd.DataFrame({"t": t - t[0], "rep": rep, "status": np.zeros(len(t), int)})[rep >= 0]
    sample = _phase_time(sample, t[cuts[:-1]] - t[0])
    for k, n in zip(columns, names, strict=True):
        sample[f"position.{n}"] = smooth[rep >= 0, k]
    for h, psi in angles.items():
        sample[f"arm_angle_rad.{h}"] = psi[rep >= 0]
    label = Path(bag).name
    written = [
        figures.joints_per_repetition(
            {label: sample},
            list(model.hand_chain(h).joint_names),
            f"{label}: {h} arm joints per repetition",
            out / f"joints_{h}.png",
        )
        for h in hands
    ]
    if angles:
        written.append(
            figures.arm_angle_per_repetition(
                {label: sample}, list(angles), f"{label}: arm angle per repetition", out / "arm_angle.png"
            )
        )
    csv = write_whole(out / "analysis.csv", pd.DataFrame([metrics]).to_csv(index=False))
    reps_csv = write_whole(out / "repetitions.csv", per_rep.to_csv(index=False))
    markdown = write_whole(
        out / "analysis.md", _markdown(bag, topic, hands, metrics, per_rep, violations, tuple(written), states.skipped)
    )
    return Analysis(metrics, per_rep, violations, out, (csv, reps_csv, markdown, *written))


Seen = tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]


def _take(seen: Seen, k: np.ndarray) -> Seen:
    """The samples ``k`` of joints, hand poses and arm angles."""
    joints, poses, angles = seen
    return joints[k], {h: T[k] for h, T in poses.items()}, {h: a[k] for h, a in angles.items()}


def _compare(first: Seen, later: Seen) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each later sample against the first repetition where the hands are nearest (module docstring, 3).

    Per later sample: the largest joint deviation [rad], the largest arm angle deviation [rad] (empty without arm
    angles) and the hands' distance to the first repetition's path [m].
    """
    features = [np.hstack([T[:, :3, 3] for T in poses.values()]) for _, poses, _ in (first, later)]
    a, b, lam, place_m = _match(*features)
    joints = np.abs(later[0] - (first[0][a] * (1 - lam)[:, None] + first[0][b] * lam[:, None])).max(axis=1)
    angles = [  # the first repetition's angle at the place, along the shorter way between its two samples
        np.abs(_wrap(later[2][h] - first[2][h][a] - lam * _wrap(first[2][h][b] - first[2][h][a]))) for h in first[2]
    ]
    return joints, np.max(angles, axis=0) if angles else np.zeros(0), place_m


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles [rad] into (-pi, pi]."""
    return np.angle(np.exp(1j * angle))


def _task(task: str | Path, robot: str | Path):
    from dualarm.tasks import load_task

    return load_task(task, None, robot)


def _reference(task):
    from dualarm.paths.build import build_reference

    return build_reference(task)


def _vertical(task) -> tuple[float, float, float]:
    return tuple(task.spec.arm_angle.vertical) if task is not None else (0.0, 0.0, 1.0)


def _window(seconds: float, dt: float) -> int:
    """An odd number of samples spanning about ``seconds`` at period ``dt``, at least 7."""
    n = max(int(round(seconds / dt)), 7)
    return n + 1 - n % 2


def _noise(raw: np.ndarray, smooth: np.ndarray, h0: float) -> np.ndarray:
    """Per column, the noise sigma of ``raw`` about its local fit ``smooth`` (module docstring, step 1)."""
    residual = raw - smooth
    mad = np.median(np.abs(residual - np.median(residual, axis=0)), axis=0)
    return mad / 0.6745 / np.sqrt(1 - h0)


def _poses(chain, q: np.ndarray) -> np.ndarray:
    from dualarm.model.kinematics import ChainKinematics

    return ChainKinematics.of(chain).poses(q)


def _start_poses(reference, hands: tuple[str, ...], poses: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each hand's start pose: the task reference's first, else its pose at the first sample."""
    if reference is None:
        return {h: poses[h][0] for h in hands}
    start = {}
    for h in hands:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = reference.hands[h].rotation[0], reference.hands[h].position[0]
        start[h] = pose
    return start


def _passes(poses: dict[str, np.ndarray], start: dict[str, np.ndarray]) -> np.ndarray:
    """The samples where the hands pass their ``start`` poses (module docstring, step 2)."""
    distance = np.zeros(len(next(iter(poses.values()))))
    for h, T in poses.items():
        rotation = np.einsum("ji,njk->nik", start[h][:3, :3], T[:, :3, :3])
        angle = np.arccos(np.clip((np.trace(rotation, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
        distance = np.maximum(
            distance, np.linalg.norm(T[:, :3, 3] - start[h][:3, 3], axis=1) + ROTATION_WEIGHT_M * angle
        )
    near = max(START_SHARE * float(distance.max()), START_MIN_M)
    cuts, inside, best = [], False, 0
    for k, d in enumerate(distance):
        if not inside and d < near:
            inside, best = True, k
        elif inside and d < distance[best]:
            best = k
        elif inside and d > 2 * near:
            inside = False
            cuts.append(best)
    if inside:
        cuts.append(best)
    return np.asarray(cuts, dtype=int)


def _match(reference: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each point's nearest place on the polyline ``reference`` (M, d): segment ends a, b, share, distance."""
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(reference).query(points)
    best = None
    for a in (np.maximum(nearest - 1, 0), nearest):
        b = np.minimum(a + 1, len(reference) - 1)
        segment = reference[b] - reference[a]
        length2 = np.maximum((segment**2).sum(axis=1), 1e-300)
        lam = np.clip(((points - reference[a]) * segment).sum(axis=1) / length2, 0.0, 1.0)
        distance = np.linalg.norm(points - (reference[a] + lam[:, None] * segment), axis=1)
        if best is None:
            best = (a, b, lam, distance)
        else:
            closer = distance < best[3]
            best = tuple(np.where(closer, new, old) for new, old in zip((a, b, lam, distance), best, strict=True))
    assert best is not None
    return best


def _limits(
    robot, names: tuple[str, ...], q: np.ndarray, sigma: np.ndarray, dt: float, metrics: dict[str, object]
) -> tuple[str, ...]:
    """Velocity, acceleration and jerk (and position) against the robot's limits, beyond their noise."""
    from scipy.signal import savgol_coeffs, savgol_filter
    from scipy.stats import norm

    window = _window(DERIVATIVE_WINDOW_S, dt)
    sigmas = float(norm.isf(FALSE_ALARM / (2 * max(q.size // window, 1))))  # over the independent estimates
    violations = []
    for order, kind in enumerate(LIMIT_KINDS, start=1):
        limit = robot.limit_array(kind, names)
        gain = float(np.linalg.norm(savgol_coeffs(window, 3, deriv=order, delta=dt)))
        ratio = np.abs(savgol_filter(q, window, 3, deriv=order, delta=dt, axis=0)) / limit
        noise = sigma * gain / limit
        k, j = np.unravel_index(np.argmax(ratio - sigmas * noise), ratio.shape)
        metrics[f"{kind}_ratio_max"] = float(ratio.max())
        metrics[f"{kind}_ratio_noise"] = float(noise.max())
        if ratio[k, j] - sigmas * noise[j] > 1 + LIMIT_SLACK:
            violations.append(
                f"{names[j]}: {kind} {ratio[k, j]:.4g} x its limit at sample {k} (noise {noise[j]:.2g})"
                + robot.assumed(kind)
            )
    lower, upper = robot.lower_upper(names)
    beyond = np.maximum(lower - q, q - upper)
    metrics["position_beyond_rad"] = float(np.nanmax(beyond))
    k, j = np.unravel_index(np.nanargmax(beyond - sigmas * sigma), beyond.shape)
    if beyond[k, j] - sigmas * sigma[j] > LIMIT_SLACK:
        violations.append(f"{names[j]}: {beyond[k, j]:.3g} rad beyond its position limit at sample {k}")
    return tuple(violations)


def _path_deviation(reference, poses: dict[str, np.ndarray]) -> float:
    """The hands' largest distance to the task's reference path [m]."""
    return max(float(_match(reference.hands[h].position, T[:, :3, 3])[3].max()) for h, T in poses.items())


def _phase_time(sample: pd.DataFrame, starts: np.ndarray) -> pd.DataFrame:
    """``t`` rewritten so that the figures' time within a repetition is the time since its start.

    The figures take repetition r to begin r periods of the first after the first (:func:`time_in_repetition`).
    """
    rep = sample["rep"].to_numpy()
    first = sample["t"].to_numpy()[rep == 0]
    period = first[-1] - first[0]
    return sample.assign(t=sample["t"].to_numpy() - starts[rep] + rep * period + first[0])


def _markdown(bag, topic, hands, metrics, per_rep, violations, written, skipped) -> str:
    lines = [
        f"# Analysis: {Path(bag).name}",
        "",
        f"`{topic}` of `{bag}`: {metrics['samples']} samples every {metrics['period_s'] * 1e3:.3g} ms, hands "
        f"{', '.join(hands)}; {skipped} message(s) without the arms' joints left out.",
        "",
        f"**{metrics['verdict']}**: the largest joint deviation between a repetition and the first at the same "
        "place is "
        f"{metrics['rep_joint_deviation_max_rad']:.3g} rad; noise alone reaches {metrics['noise_floor_rad']:.3g} rad "
        f"(sigma {metrics['noise_rad']:.3g} rad, estimated from the data); the threshold is "
        f"{metrics['threshold_rad']} rad above that.",
        "",
        "| metric | value |",
        "|---|---|",
        *(f"| {k} | {v:.6g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in metrics.items()),
        "",
        "Repetitions:",
        "",
        "| " + " | ".join(per_rep.columns) + " |",
        "|" + "---|" * len(per_rep.columns),
        *("| " + " | ".join(f"{v:.6g}" for v in row) + " |" for row in per_rep.itertuples(index=False)),
        "",
    ]
    if metrics["noise_floor_rad"] > metrics["threshold_rad"]:
        lines += [
            f"The noise floor is above the threshold: the first repetition passes one hand place with joints "
            f"{metrics['noise_floor_rad']:.3g} rad apart (a self-motion, or a failed stretch), so the same place "
            "is ambiguous there.",
            "",
        ]
    lines += (
        ["Limits exceeded beyond their noise:", "", *(f"- {v}" for v in violations)]
        if violations
        else ["No limit exceeded beyond its noise."]
    )
    if written:
        lines += ["", "Figures:", ""] + [f"![{p.stem}]({p.name})" for p in written]
    return "\n".join(lines) + "\n"
