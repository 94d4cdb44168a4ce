"""Seeing a plan: the standalone HTML in a real browser (Debian's chromium), the live server."""

from __future__ import annotations

import ipaddress
import socket
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROBOT_NAMES, load

import nearopt
from nearopt.paper_example import COST, THETA_0, THETA_E
from nearopt.viz.viewer import export_html, mesh_parts, show

CHROMIUM = Path("/usr/bin/chromium")
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
]
COUNT_MESHES = "() => { let c = 0; viewer.scene.traverse(o => { if (o.isMesh) c++; }); return c; }"


@pytest.fixture(scope="module")
def plans() -> dict[str, nearopt.PlanResult]:
    """Short plans: the paper's example and a panda motion (a few iterations suffice here)."""
    return {
        "two_link": nearopt.plan(
            load("two_link"),
            THETA_0,
            THETA_E,
            COST,
            grid=60,
            max_iterations=20,
        ),
        "panda": nearopt.plan(
            load("panda"),
            [0, -0.5, 0, -2, 0, 1.5, 0.8],
            [1, 0, 0.5, -1.5, 0, 2, 0],
            nearopt.TimeCost(),
            grid=60,
            max_iterations=3,
        ),
    }


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


WIDTH, HEIGHT = 640, 480
# world placement of the node at `path` relative to the scene's root node /meshcat (row-major)
PLACEMENT = """(path) => {
  const root = viewer.scene_tree.find(['meshcat']).object;
  const node = viewer.scene_tree.find(path).object;
  root.updateMatrixWorld(true);
  const m = root.matrixWorld.clone().invert().multiply(node.matrixWorld);
  return m.transpose().toArray();
}"""
# pixel (column, row) of the robot's base (the origin of /meshcat) in the view
BASE_PIXEL = f"""() => {{
  const root = viewer.scene_tree.find(['meshcat']).object;
  root.updateMatrixWorld(true);
  const v = root.localToWorld(viewer.camera.position.clone().set(0, 0, 0)).project(viewer.camera);
  return [(v.x + 1) / 2 * {WIDTH}, (1 - v.y) / 2 * {HEIGHT}];
}}"""


def _visible(page: object, node: list[str], visible: bool) -> None:
    page.evaluate(
        f"viewer.scene_tree.find({node!r}).object.visible = {str(visible).lower()};"
        "viewer.set_dirty();"
    )


def _open(page: object, url: str, geometries: int) -> None:
    """Load a page and wait until every visual's mesh is in the scene (decoded asynchronously)."""
    page.goto(url)
    page.wait_for_function(f"() => ({COUNT_MESHES})() >= {geometries}", timeout=60_000)
    page.wait_for_timeout(500)


def _settled_picture(page: object, path: Path, timeout: float = 20.0) -> np.ndarray:
    """A screenshot once the picture has stopped changing: two in a row, 250 ms apart, that
    differ in no pixel by more than 25 of 255 (the meshes' count can be reached before every
    one has its placement and material, and a loaded machine draws late)."""
    page.screenshot(path=path)
    last = _pixels(path)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        page.wait_for_timeout(250)
        page.screenshot(path=path)
        now = _pixels(path)
        if not np.any(np.abs(now - last) > 25):
            return now
        last = now
    return last


@pytest.mark.parametrize("name", ["two_link", "panda"])
def test_exported_page_frames_the_motion_on_the_floor_offline(
    name: str, plans: dict[str, nearopt.PlanResult], tmp_path: Path
) -> None:
    """The offline page in a real browser: it opens paused in the start pose, the robot stands
    on the ground grid, the motion fills the view, the page plays its motion, nothing is fetched
    from the network, and panda's page is under 8 MB."""
    playwright = pytest.importorskip("playwright.sync_api")
    assert CHROMIUM.exists(), "make test installs Debian's chromium (apt)"
    result = plans[name]
    robot = result.robot
    html = export_html(result, tmp_path / f"{name}.html")
    assert html.stat().st_size < 8e6, html.stat().st_size
    visual = robot.visual_model()
    requests: list[str] = []
    shot = {}
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
        page.on("request", lambda request: requests.append(request.url))
        _open(page, html.resolve().as_uri(), len(visual.geometryObjects))
        assert page.evaluate("viewer.animator.playing") is False
        assert page.evaluate("viewer.animator.duration") == pytest.approx(
            result.duration, abs=1.5 / 60
        )
        # the first frame is the start pose: every visual where Pinocchio places it at θ0
        data, gdata = robot.model.createData(), pin.GeometryData(visual)
        pin.forwardKinematics(robot.model, data, np.asarray(result.trajectory(np.zeros(1), 0))[0])
        pin.updateGeometryPlacements(robot.model, data, visual, gdata)
        for g, placement in zip(visual.geometryObjects, gdata.oMg, strict=True):
            shown = page.evaluate(PLACEMENT, ["meshcat", robot.name, "visuals", g.name])
            np.testing.assert_allclose(
                np.reshape(shown, (4, 4)), placement.homogeneous, atol=1e-6, err_msg=g.name
            )
        base = page.evaluate(BASE_PIXEL)

        def screenshot(label: str) -> np.ndarray:
            page.wait_for_timeout(300)
            page.screenshot(path=tmp_path / f"{label}.png")
            return _pixels(tmp_path / f"{label}.png")

        shot["start"] = screenshot("start")
        page.evaluate("viewer.animator.seek(0); viewer.set_dirty();")
        shot["seek0"] = screenshot("seek0")
        _visible(page, ["meshcat", "floor"], False)
        _visible(page, ["meshcat", "trails"], False)
        robots = []
        for t in (0.0, 0.5 * result.duration, result.duration):
            page.evaluate(f"viewer.animator.seek({t}); viewer.set_dirty();")
            robots.append(screenshot(f"robot{t}"))
        _visible(page, ["meshcat", robot.name], False)
        shot["nothing"] = screenshot("nothing")
        _visible(page, ["meshcat", "floor"], True)
        shot["floor"] = screenshot("floor")
        browser.close()
    assert requests == [html.resolve().as_uri()], requests
    np.testing.assert_allclose(shot["start"], shot["seek0"], atol=2.0)  # opens at t = 0

    def mask(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.any(np.abs(a - b) > 25, axis=2)

    arm = [mask(r, shot["nothing"]) for r in robots]
    floor = mask(shot["floor"], shot["nothing"])
    assert mask(robots[0], robots[-1]).mean() > 0.001, "the arm moves"
    # the motion fills the view: its bounding box spans ≥ 40 % of the smaller side
    rows, cols = np.nonzero(np.logical_or.reduce(arm))
    span = max(rows.max() - rows.min(), cols.max() - cols.min())
    assert span >= 0.4 * min(WIDTH, HEIGHT), span
    # the ground grid is drawn at the base or just below it (under an arm that reaches below its
    # base), not above it; the robot does not reach below it there
    x, y = int(round(base[0])), int(round(base[1]))
    assert floor[max(y - 5, 0) : y + 40, max(x - 40, 0) : x + 40].any(), (x, y)
    assert np.nonzero(floor.any(axis=1))[0].max() > y + 40, "seen from above: its near edge"
    lowest = np.nonzero(arm[0].any(axis=1))[0].max()
    assert lowest <= y + 0.06 * HEIGHT, (lowest, y)


def _listening(port: int) -> list[str]:
    """Local addresses of the sockets listening on ``port`` (IPv4 and IPv6), from /proc."""
    found = []
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        if not Path(table).exists():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            address, hex_port = fields[1].split(":")
            if fields[3] == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                raw = bytes.fromhex(address)
                if width == 8:
                    found.append(str(ipaddress.IPv4Address(raw[::-1])))
                else:
                    words = b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4))
                    found.append(str(ipaddress.IPv6Address(words)))
    return found


def test_live_server_listens_on_loopback_only(plans: dict[str, nearopt.PlanResult]) -> None:
    with show(plans["two_link"]) as viewer:
        web_port = int(viewer.url.split(":")[2].split("/")[0])
        zmq_port = int(viewer.zmq_url.rsplit(":", 1)[1])
        assert viewer.url.startswith("http://127.0.0.1:")
        for port in (web_port, zmq_port):
            assert _listening(port) == ["127.0.0.1"], (port, _listening(port))
        with socket.create_connection(("127.0.0.1", web_port), timeout=5) as conn:
            conn.sendall(b"GET /static/ HTTP/1.0\r\n\r\n")
            assert conn.recv(12).startswith(b"HTTP/1.")
    assert _listening(web_port) == []  # closed


def test_live_server_stops_when_its_parent_dies(tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "parent.py"
    script.write_text(
        "import numpy as np, nearopt, sys, time\n"
        "from nearopt.viz.viewer import show\n"
        "r = nearopt.Robot.from_name('two_link')\n"
        "res = nearopt.plan(r, [0.5, 0.2], [1.0, 1.0], grid=20, max_iterations=1)\n"
        "viewer = show(res)\n"
        "print(viewer.url, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    url = ""
    while "http" not in url:
        url = parent.stdout.readline()
    port = int(url.split(":")[2].split("/")[0])
    assert _listening(port) == ["127.0.0.1"]
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    for _ in range(50):
        if not _listening(port):
            break
        time.sleep(0.1)
    assert _listening(port) == []


def test_live_and_offline_pages_look_the_same(
    plans: dict[str, nearopt.PlanResult], tmp_path: Path
) -> None:
    """show() and export_html() send the same scene: the same picture on load."""
    playwright = pytest.importorskip("playwright.sync_api")
    result = plans["panda"]
    geometries = len(result.robot.visual_model().geometryObjects)
    html = export_html(result, tmp_path / "panda.html")
    pictures = []
    with show(result) as viewer, playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        for url in (html.resolve().as_uri(), viewer.url):
            page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
            _open(page, url, geometries)
            pictures.append(_settled_picture(page, tmp_path / "shot.png"))
        browser.close()
    differ = np.any(np.abs(pictures[0] - pictures[1]) > 25, axis=2)
    assert differ.mean() < 0.005, differ.mean()


@pytest.mark.parametrize("name", [n for n in ROBOT_NAMES if n != "two_link"])
def test_converted_meshes_are_the_ones_pinocchio_loaded(name: str) -> None:
    """Every mesh the page carries has the vertices' extent and triangle count of the mesh
    Pinocchio (assimp, through coal) loaded from the same file and scale."""
    for g in load(name).visual_model().geometryObjects:
        if not g.meshPath:
            continue
        parts = mesh_parts(g.meshPath, tuple(float(x) for x in g.meshScale))
        ours = np.vstack([vertices for vertices, _, _ in parts])
        bvh = g.geometry
        theirs = np.asarray(bvh.vertices())
        np.testing.assert_allclose(ours.min(axis=0), theirs.min(axis=0), atol=1e-6)
        np.testing.assert_allclose(ours.max(axis=0), theirs.max(axis=0), atol=1e-6)
        count = sum(len(faces) for _, faces, _ in parts)  # assimp drops a few degenerate ones
        assert abs(count - bvh.num_tris) <= 1e-3 * bvh.num_tris, (g.name, count, bvh.num_tris)
        for vertices, faces, rgba in parts:
            assert faces.min() >= 0 and faces.max() < len(vertices)
            assert np.all((rgba >= 0) & (rgba <= 1)) and rgba.shape == (4,)


def test_the_exported_page_draws_the_obstacles_in_place(tmp_path: Path) -> None:
    """A plan in a cell: the page holds every obstacle where the scene puts it, and they show."""
    playwright = pytest.importorskip("playwright.sync_api")
    from nearopt.collision import Box, Capsule, Cylinder, HalfSpace, Obstacle, Scene, Sphere

    cell = Scene(
        (
            Obstacle("table", Box((1.2, 1.2, 0.04)), (0.3, 0.0, -0.03)),
            Obstacle("post", Cylinder(0.05, 1.0), (0.45, 0.0, 0.5), (0.0, 0.1, 0.0)),
            Obstacle("ball", Sphere(0.08), (-0.4, 0.3, 0.5)),
            Obstacle("bar", Capsule(0.03, 0.4), (-0.4, -0.4, 0.4), (0.3, 0.0, 0.0)),
            Obstacle("floor", HalfSpace((0.0, 0.0, 1.0), -0.2)),
        )
    )
    result = nearopt.plan(
        load("ur5"),
        [-0.8, -1.2, 1.2, -1.5, -1.57, 0.0],
        [0.8, -1.2, 1.2, -1.5, -1.57, 0.0],
        nearopt.TimeCost(),
        grid=60,
        max_iterations=2,
        scene=cell,
    )
    html = export_html(result, tmp_path / "cell.html")
    visual = result.robot.visual_model()
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
        _open(page, html.resolve().as_uri(), len(visual.geometryObjects) + 7)
        for ob in cell.obstacles[:4]:
            shown = np.reshape(page.evaluate(PLACEMENT, ["meshcat", "obstacles", ob.name]), (4, 4))
            np.testing.assert_allclose(shown[:3, 3], ob.position, atol=1e-9, err_msg=ob.name)
            np.testing.assert_allclose(shown[:3, :3], ob.rotation(), atol=1e-9, err_msg=ob.name)
        # the floor's slab: its top face on z = −0.2
        slab = np.reshape(
            page.evaluate(PLACEMENT, ["meshcat", "obstacles", "floor", "slab"]), (4, 4)
        )
        assert slab[2, 3] + 0.005 == pytest.approx(-0.2, abs=1e-9)
        page.wait_for_timeout(300)
        page.screenshot(path=tmp_path / "with.png")
        _visible(page, ["meshcat", "obstacles"], False)
        page.wait_for_timeout(300)
        page.screenshot(path=tmp_path / "without.png")
        browser.close()
    changed = np.any(
        np.abs(_pixels(tmp_path / "with.png") - _pixels(tmp_path / "without.png")) > 25, axis=2
    )
    assert changed.mean() > 0.05  # the obstacles cover a good part of the view


def test_the_exported_page_marks_a_goal_pose_with_a_triad(tmp_path: Path) -> None:
    playwright = pytest.importorskip("playwright.sync_api")
    goal = nearopt.ToolPose((0.5, 0.2, 0.3), (1.0, 0.0, 0.0, 0.0))
    result = nearopt.plan(
        load("panda"), [0, -0.5, 0, -2, 0, 1.5, 0.8], goal, grid=60, max_iterations=2
    )
    html = export_html(result, tmp_path / "goal.html")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
        _open(page, html.resolve().as_uri(), len(result.robot.visual_model().geometryObjects))
        shown = np.reshape(page.evaluate(PLACEMENT, ["meshcat", "targets", "target0"]), (4, 4))
        browser.close()
    np.testing.assert_allclose(shown, goal.placement().homogeneous, atol=1e-9)


def test_the_page_of_a_task_marks_every_target(tmp_path: Path) -> None:
    """A task's page: a triad at each target (a joint target: the tip's placement there) and
    none more; the animation lasts the whole task."""
    playwright = pytest.importorskip("playwright.sync_api")
    robot = load("panda")
    stop = np.array([0.4, -0.3, 0.2, -2.2, 0.1, 1.9, 0.6])
    goal = nearopt.ToolPose((0.5, 0.2, 0.3), (1.0, 0.0, 0.0, 0.0))
    result = nearopt.plan_task(
        robot,
        [0, -0.5, 0, -2, 0, 1.5, 0.8],
        [nearopt.Target(stop, name="stop"), goal],
        settings=nearopt.PlanSettings(grid=60, max_iterations=1),
    )
    html = export_html(result, tmp_path / "task.html")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
        _open(page, html.resolve().as_uri(), len(robot.visual_model().geometryObjects))
        shown = [
            np.reshape(page.evaluate(PLACEMENT, ["meshcat", "targets", f"target{k}"]), (4, 4))
            for k in range(2)
        ]
        names = page.evaluate(
            "(path) => Object.keys(viewer.scene_tree.find(path).children)", ["meshcat", "targets"]
        )
        browser.close()
    np.testing.assert_allclose(shown[0], robot.frame_placement(stop).homogeneous, atol=1e-9)
    np.testing.assert_allclose(shown[1], goal.placement().homogeneous, atol=1e-9)
    assert sorted(names) == ["target0", "target1"]
