"""``run.rrd`` opened in Rerun's own native viewer, headless (``rerun.experimental.ViewerClient``).

The viewer renders with Mesa's software Vulkan (``apt-get install mesa-vulkan-drivers``); without a
Vulkan driver the tests are skipped, saying what to install. What is asserted is what the viewer
itself reports: its views' errors, its transform graph, and the pixels of its 3D view.
"""

import io
import json
import shutil
import socket
import sys
import time
import xml.etree.ElementTree as ET
from collections import defaultdict, deque
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dualarm.model.robot import load_robot
from dualarm.record.sink import recorded_stages, shown_stage
from tests.helpers import OTHER_RUNS, SHIPPED

RERUN = str(Path(sys.executable).with_name("rerun"))
#: The 3D view's target frame (the blueprint's origin "/").
TARGET = "tf#/"
#: Robot pixels must stay this far from the 3D view's edges (the whole robot in frame) [px].
MARGIN_PX = 4

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(
        not any(
            Path(d).is_dir() and any(Path(d).glob("*.json")) for d in ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d")
        )
        or shutil.which(RERUN) is None,
        reason="the Rerun viewer tests need a Vulkan driver: apt-get install mesa-vulkan-drivers",
    ),
]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _until(check, what: str, timeout_s: float = 120.0, period_s: float = 0.1):
    """Poll ``check()`` until it returns something other than None."""
    started = time.monotonic()
    while time.monotonic() - started < timeout_s:
        try:
            found = check()
        except Exception:  # noqa: BLE001 - the viewer is not listening yet
            found = None
        if found is not None:
            return found
        time.sleep(period_s)
    raise TimeoutError(f"the viewer: {what} after {timeout_s} s")


@pytest.fixture(scope="module", params=[*sorted(SHIPPED), *sorted(OTHER_RUNS)])
def opened(request):
    """Each shipped task's run through every stage, and each of :data:`OTHER_RUNS` (the Panda, a run recorded up to the
    IK), opened in a headless viewer; (client, store id, the stages recorded, the end of the recording's time [s], the
    run's robot)."""
    from rerun.experimental import ViewerClient

    runs = request.getfixturevalue("shipped_runs" if request.param in SHIPPED else "other_runs")
    run = runs[request.param]
    client = ViewerClient.spawn(headless=True, port=_free_port(), hide_welcome_screen=True, executable_path=RERUN)
    try:
        _until(client.get_state, "no answer")
        (store,) = client.open(str(run / "run.rrd")).store_ids

        def loaded():
            state = client.get_state()
            recording = next((r for r in state.recordings if r.store_id == store), None)
            return True if recording is not None and recording.timelines and not state.loading else None

        _until(loaded, "the recording is still loading")
        counts: list[tuple[int, int]] = []

        def settled():  # open returns before every chunk is in the transform graph: wait until it stops growing
            graph = client.get_transform_graph()
            counts.append((len(graph["frames"]), len(graph["edges"])))
            return True if len(counts) >= 4 and len(set(counts[-4:])) == 1 and not graph.get("missing_chunks") else None

        _until(settled, "the transform graph is still growing", period_s=0.5)
        manifest = json.loads((run / "manifest.json").read_text())
        (timeline,) = [t for t in client.get_recording_schema(store).timelines if t.name == "time"]
        stages = recorded_stages(manifest["record"], manifest["stages"])
        yield client, store, stages, timeline.end / 1e9, load_robot(manifest["robot_dir"])
    finally:
        client.quit()


def _show(client, t_s: float) -> None:
    """Pause at motion time ``t_s`` and wait for a painted frame (so the views' reports are current)."""
    client.set_time("time", duration=t_s, play_state="paused")
    client.take_screenshot(max_size=64)


def _joined(graph: dict) -> set[str]:
    """The frames joined to :data:`TARGET` by some chain of edges."""
    adjacent: dict[str, set[str]] = defaultdict(set)
    for edge in graph["edges"]:
        adjacent[edge["parent"]].add(edge["child"])
        adjacent[edge["child"]].add(edge["parent"])
    seen, todo = {TARGET}, deque([TARGET])
    while todo:
        for frame in adjacent[todo.popleft()] - seen:
            seen.add(frame)
            todo.append(frame)
    return seen


def test_every_view_reports_nothing_at_start_middle_and_end(opened):
    client, _, _, end, _ = opened
    for t in (0.0, end / 2, end):
        _show(client, t)
        errors = {
            f"{v.name} [{v.view_class}]": sorted({r.summary for r in v.reports})[:3]
            for v in client.get_state().views
            if v.reports
        }
        assert not errors, f"t = {t:g} s: {errors}"


def test_every_stage_robot_is_joined_to_the_3d_views_frame(opened):
    """Every link of the URDF (read with ElementTree), for every stage the run recorded."""
    client, _, stages, end, robot = opened
    links = {link.get("name") for link in ET.parse(robot.urdf.path).getroot().iter("link")}
    for t in (0.0, end / 2):
        _show(client, t)
        joined = _joined(client.get_transform_graph())
        for stage in stages:
            missing = sorted(f"{stage}/{link}" for link in links if f"{stage}/{link}" not in joined)
            assert not missing, (
                f"t = {t:g} s: {len(missing)} frames of the {stage} robot are not joined to {TARGET},"
                f" e.g. {missing[:3]}"
            )


def test_the_3d_view_draws_the_whole_robot(opened):
    """In the view the run opens on, hiding its robot (the executed one, when the run recorded the execution) changes at
    least 1 % of the pixels, none near the edges."""
    client, _, stages, end, _ = opened
    stage = shown_stage(stages)
    view = next(v.view_id for v in client.get_state().views if v.name == f"{stage}: robot and hand paths")

    def shot() -> np.ndarray:
        _show(client, end / 2)
        return np.asarray(Image.open(io.BytesIO(client.take_screenshot(view))).convert("RGB")).astype(int)

    shown = shot()
    blueprint = client.get_blueprint()
    key = f"/view/{view}/ViewContents"
    before = blueprint.blueprint.get(key)
    hiding = {"ViewContents": {"query": [*before["ViewContents"]["query"], f"- /{stage}/**"]}}
    blueprint.blueprint[key] = hiding
    client.set_blueprint(blueprint.blueprint, store_id=blueprint.store_id)
    _until(lambda: True if client.get_blueprint().blueprint.get(key) == hiding else None, "the view is not changed")
    try:
        hidden = shot()
    finally:
        if before is not None:
            blueprint.blueprint[key] = before
            client.set_blueprint(blueprint.blueprint, store_id=blueprint.store_id)
    robot = np.abs(shown - hidden).max(axis=2) > 30
    h, w = robot.shape
    assert robot.sum() >= 0.01 * h * w, f"only {robot.sum()} of {h * w} pixels are the robot's"
    ys, xs = np.nonzero(robot)
    assert MARGIN_PX <= xs.min() and MARGIN_PX <= ys.min() and xs.max() < w - MARGIN_PX and ys.max() < h - MARGIN_PX, (
        "the robot reaches the view's edge: cut off"
    )


def test_the_run_opens_on_its_own_layout(opened):
    """The views the viewer shows are the run's blueprint (sent before the data), not a layout the viewer made up."""
    client, _, stages, _, _ = opened
    names = {v.name for v in client.get_state().views}
    assert f"{shown_stage(stages)}: robot and hand paths" in names, names
    if "execute" in stages:
        plots = {"hand error [m] (execute)", "velocity / limit", "acceleration / limit", "jerk / limit", "contacts"}
        assert plots <= names, names
    assert {stage for stage in stages if stage != "approach"} <= names, names  # the "stages" tab: a 3D view per stage


def _matches(query: list[str], entity: str) -> bool:
    """Whether a view's contents ``query`` (Rerun's "+ /path/**" and "- /path/**" rules, the last match wins) holds
    ``entity``."""
    verdict = False
    for rule in query:
        sign, pattern = rule[0], rule[1:].strip()
        base = pattern.removesuffix("/**")
        if entity == base or (pattern.endswith("/**") and entity.startswith(base.rstrip("/") + "/")):
            verdict = sign == "+"
    return verdict


def test_every_view_of_the_blueprint_shows_data(opened):
    """No view the run opens on is empty: each plot's contents hold a logged scalar series, each 3D view's some logged
    data, by the viewer's own blueprint and recording schema."""
    client, store, _, _, _ = opened
    blueprint = client.get_blueprint().blueprint
    plots = client.get_recording_schema(store, entity_path="/plots", max_entities=10**6).entities
    scalars = {e.entity_path for e in plots if any(c.component == "Scalars:scalars" for c in e.components)}
    logged = {e.entity_path for e in client.get_recording_schema(store, paths_only=True, max_entities=10**6).entities}
    empty = []
    for view in client.get_state().views:
        query = blueprint[f"/view/{view.view_id}/ViewContents"]["ViewContents"]["query"]
        query = [query] if isinstance(query, str) else query
        shown = scalars if view.view_class == "TimeSeries" else logged
        if not any(_matches(query, entity) for entity in shown):
            empty.append(f"{view.name} [{view.view_class}]: {query}")
    assert not empty


#: The unit of each plot of the blueprint, by a word of its name.
UNITS = {"[m]": "m", "[rad]": "rad", "/ limit": "ratio", "contacts": "count"}


def test_every_plot_shows_a_range_no_narrower_than_its_units_floor(opened):
    """Each time series view's y-range, as the viewer holds it, is at least its unit's floor wide (1e-4 m, 1e-3 rad):
    a series constant up to rounding is drawn flat, not as noise filling the plot."""
    from dualarm.record.sink import PLOT_FLOORS

    client, _, _, _, _ = opened
    blueprint = client.get_blueprint().blueprint
    narrow = {}
    for view in client.get_state().views:
        if view.view_class != "TimeSeries":
            continue
        unit = next(unit for word, unit in UNITS.items() if word in view.name)
        low, high = blueprint[f"/view/{view.view_id}/ScalarAxis"]["ScalarAxis"]["range"]
        if high - low < PLOT_FLOORS[unit] * (1 - 1e-9):
            narrow[view.name] = (low, high)
    assert not narrow


@pytest.mark.parametrize("opened", ["triangle"], indirect=True)
def test_the_held_arm_angle_is_drawn_flat_within_its_plot(opened, request):
    """MC-Inverse holds the triangle's arm angle: its samples (read from run.mcap with the mcap reader) spread less than
    1e-12 rad, and the viewer's arm-angle plot spans at least 1e-3 rad around them."""
    from mcap.reader import make_reader

    client, _, _, _, _ = opened
    run = request.getfixturevalue("shipped_runs")["triangle"]
    with (run / "run.mcap").open("rb") as f:
        psi = np.array(
            [
                list(json.loads(message.data)["arm_angle_rad"].values())
                for _, _, message in make_reader(f).iter_messages(topics=["/ik/sample"])
            ]
        )
    assert psi.size and np.ptp(psi, axis=0).max() < 1e-12
    view = next(v for v in client.get_state().views if v.name == "arm angle [rad]")
    low, high = client.get_blueprint().blueprint[f"/view/{view.view_id}/ScalarAxis"]["ScalarAxis"]["range"]
    assert high - low >= 1e-3 * (1 - 1e-9) and low <= psi.min() and psi.max() <= high


@pytest.mark.parametrize("opened", ["carry_box"], indirect=True)
def test_the_carried_box_is_drawn_and_moves_with_the_hands(opened, request):
    """carry_box: hiding the box's entity changes the executed view's pixels at the start and where the master hand is
    highest (read from run.mcap with the mcap reader), and the box's pixels move up between the two."""
    from mcap.reader import make_reader

    from dualarm.tasks import load_task

    client, _, _, _, _ = opened
    run = request.getfixturevalue("shipped_runs")["carry_box"]
    carried = load_task("carry_box").spec.object
    with (run / "run.mcap").open("rb") as f:
        samples = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/execute/sample"])]
    heights = np.array([s["hand_position"][carried.master]["z"] for s in samples])
    top = samples[int(np.argmax(heights))]["t"]
    assert heights.max() - heights[0] > 0.1  # the task lifts the box 0.2 m
    view = next(v.view_id for v in client.get_state().views if v.name == "execute: robot and hand paths")
    blueprint = client.get_blueprint()
    key = f"/view/{view}/ViewContents"
    before = blueprint.blueprint[key]
    hiding = {"ViewContents": {"query": [*before["ViewContents"]["query"], f"- /world/execute/{carried.name}/**"]}}

    def shot(t: float) -> np.ndarray:
        _show(client, t)
        return np.asarray(Image.open(io.BytesIO(client.take_screenshot(view))).convert("RGB")).astype(int)

    shown = {t: shot(t) for t in (0.0, top)}
    blueprint.blueprint[key] = hiding
    client.set_blueprint(blueprint.blueprint, store_id=blueprint.store_id)
    _until(lambda: True if client.get_blueprint().blueprint.get(key) == hiding else None, "the view is not changed")
    try:
        rows = {}
        for t, image in shown.items():
            box = np.abs(image - shot(t)).max(axis=2) > 30
            assert box.sum() > 200, f"t = {t:g} s: {box.sum()} pixels of the box"
            rows[t] = np.nonzero(box)[0].mean()
    finally:
        blueprint.blueprint[key] = before
        client.set_blueprint(blueprint.blueprint, store_id=blueprint.store_id)
    assert rows[top] < rows[0.0] - 10  # up the image: the box rose with the hands


@pytest.mark.parametrize("opened", ["carry_box"], indirect=True)
def test_each_stage_plots_on_its_own_clock(opened, request):
    """carry_box: the IK runs on the task's clock (20 s), the execution on its own (6.3 s). The viewer's blueprint gives
    each hand error plot a time axis, unlinked from the others, from 0 to its stage's last sample (read from run.mcap
    with the mcap reader), and every plot an axis that ends within the recording."""
    from mcap.reader import make_reader

    client, _, _, end, _ = opened
    run = request.getfixturevalue("shipped_runs")["carry_box"]
    with (run / "run.mcap").open("rb") as f:
        last = {
            topic.split("/")[1]: max(
                json.loads(m.data)["t"] for _, _, m in make_reader(f).iter_messages(topics=[topic])
            )
            for topic in ("/ik/sample", "/execute/sample")
            if not f.seek(0)
        }
    assert last["ik"] > 2 * last["execute"]
    blueprint = client.get_blueprint().blueprint
    axes = {
        v.name: blueprint[f"/view/{v.view_id}/TimeAxis"]["TimeAxis"]
        for v in client.get_state().views
        if v.view_class == "TimeSeries"
    }
    for name, axis in axes.items():
        assert axis["link"] == "Independent", name
        assert 0 <= axis["view_range"]["end"]["Absolute"] / 1e9 <= end + 1e-9, name
    for stage, t in last.items():
        span = axes[f"hand error [m] ({stage})"]["view_range"]
        assert span["start"]["Absolute"] == 0 and abs(span["end"]["Absolute"] / 1e9 - t) <= 1e-6, stage
