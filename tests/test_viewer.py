"""Seeing a plan: the standalone HTML in a real browser (Debian's chromium), the live server."""

from __future__ import annotations

import ipaddress
import socket
from pathlib import Path

import numpy as np
import pytest
from conftest import load

import nearopt
from nearopt.paper_example import COST, THETA_0, THETA_E
from nearopt.viz.viewer import export_html, show

CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update"]
COUNT_MESHES = "() => { let c = 0; viewer.scene.traverse(o => { if (o.isMesh) c++; }); return c; }"


@pytest.fixture(scope="module")
def plans() -> dict[str, nearopt.PlanResult]:
    """Short plans: the paper's example and a panda motion (a few iterations suffice here)."""
    return {
        "two_link": nearopt.plan(
            load("two_link"), THETA_0, THETA_E, COST, grid=60, max_iterations=20,
        ),
        "panda": nearopt.plan(
            load("panda"), [0, -0.5, 0, -2, 0, 1.5, 0.8], [1, 0, 0.5, -1.5, 0, 2, 0],
            nearopt.TimeCost(), grid=60, max_iterations=3,
        ),
    }


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


@pytest.mark.parametrize("name", ["two_link", "panda"])
def test_exported_html_plays_in_a_real_browser_offline(
    name: str, plans: dict[str, nearopt.PlanResult], tmp_path: Path
) -> None:
    playwright = pytest.importorskip("playwright.sync_api")
    assert CHROMIUM.exists(), "make test installs Debian's chromium (apt)"
    result = plans[name]
    html = export_html(result, tmp_path / f"{name}.html")
    geometries = len(result.robot.visual_model().geometryObjects)
    requests: list[str] = []
    shots = {}
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": 640, "height": 480})
        page.on("request", lambda request: requests.append(request.url))
        page.goto(html.resolve().as_uri())
        # every visual's mesh is in the scene (meshes are decoded asynchronously)
        page.wait_for_function(f"() => ({COUNT_MESHES})() >= {geometries}", timeout=60_000)
        assert page.evaluate("viewer.animator.duration") == pytest.approx(
            result.duration, abs=1.5 / 60
        )
        page.evaluate("viewer.animator.pause()")
        for label, t in (("early", 0.1 * result.duration), ("late", 0.8 * result.duration)):
            page.evaluate(f"viewer.animator.seek({t}); viewer.set_dirty();")
            page.wait_for_timeout(300)
            shots[label] = tmp_path / f"{label}.png"
            page.screenshot(path=shots[label])
        # the same view without the arm: what is left is background, grid and trails
        page.evaluate(
            f"viewer.scene_tree.find(['meshcat', '{result.robot.name}']).object.visible = false;"
            "viewer.set_dirty();"
        )
        page.wait_for_timeout(300)
        shots["empty"] = tmp_path / "empty.png"
        page.screenshot(path=shots["empty"])
        browser.close()
    early, late, empty = (_pixels(shots[k]) for k in ("early", "late", "empty"))
    drawn = np.any(np.abs(early - empty) > 30, axis=2)
    assert drawn.mean() > 0.002, "the arm covers part of the view"
    moved = np.any(np.abs(early - late) > 30, axis=2)
    assert moved.mean() > 0.001, "the arm is somewhere else at the two times"
    assert requests == [html.resolve().as_uri()], requests


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
