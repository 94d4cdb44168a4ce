"""Watch a plan in the browser: a meshcat animation, live (127.0.0.1 only) or as a standalone file.

The arm is drawn from its URDF visuals (meshes of example-robot-data, primitives of the bundled
arm) by Pinocchio's ``MeshcatVisualizer``, which has no animation support of its own: the frames of
meshcat's Animation track (play / pause / scrub in the browser's "Animations" panel) are built here
from the kinematics, one per 1/fps s of the motion, in real time. The tip's path is drawn as a
trail, and the straight joint line the planner started from as a grey one.

Two ways to look at it:

* :func:`export_html` writes one self-contained HTML file (meshcat's viewer script and every
  command inlined, meshes included) without opening any socket: the scene is recorded by a
  stand-in for meshcat's window instead of being sent to a server. It opens from disk offline.
* :func:`show` starts a meshcat server bound to 127.0.0.1 only (meshcat 0.3.2's own server
  listens on every interface) and sends the scene to it; open the printed URL.
"""

from __future__ import annotations

import atexit
import base64
import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack
from meshcat.animation import Animation
from meshcat.servers.tree import SceneTree, find_node, walk
from pinocchio.visualize import MeshcatVisualizer

from ..errors import ConfigurationError, NearoptError
from ..outputs import write_atomically
from .geometry import plane_axes, tip_path

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..planning import PlanResult
    from ..robot import Robot
    from ..trajectory import Trajectory

__all__ = ["export_html", "show", "LiveViewer", "scene_html", "plan_html"]

_VIEWER_JS = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"


class _Recorder:
    """A meshcat window that keeps the scene tree instead of sending commands to a server."""

    def __init__(self) -> None:
        self.tree = SceneTree()

    def send(self, command: object) -> None:
        data = command.lower()
        packed = umsgpack.packb(data)
        path = [p for p in data["path"].split("/") if p]
        node = find_node(self.tree, path)
        kind = data["type"]
        if kind == "set_object":
            node.object, node.properties = packed, []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            node.animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                if path[-1] in parent:
                    del parent[path[-1]]
            else:
                self.tree = SceneTree()

    def html(self) -> str:
        """The scene as one HTML page: meshcat's viewer and the commands, in order, inline."""
        commands = []
        for node in walk(self.tree):
            for blob in (node.object, *node.properties, node.transform, node.animation):
                if blob is not None:
                    commands.append(f'run("{base64.b64encode(blob).decode("ascii")}");')
        return _PAGE.format(viewer=_VIEWER_JS.read_text(), commands="\n".join(commands))


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>nearopt</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>{viewer}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
function run(b64) {{
  var text = atob(b64), bytes = new Uint8Array(text.length);
  for (var i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  viewer.handle_command_bytearray(bytes);
}}
{commands}
</script>
</body>
</html>
"""


def _draw(
    vis: meshcat.Visualizer,
    robot: Robot,
    trajectory: Trajectory,
    initial: Trajectory | None,
    fps: float,
) -> None:
    """Load the arm, its animation and the trails into a meshcat visualizer."""
    if not (np.isfinite(fps) and fps > 0):
        raise ConfigurationError(f"fps must be a positive number, got {fps}")
    visual = robot.visual_model()
    viz = MeshcatVisualizer(robot.model, visual, visual)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName=robot.name)
    model, data = robot.model, robot.model.createData()
    gdata = pin.GeometryData(visual)
    frames = int(np.ceil(trajectory.duration * fps - 1e-9))
    q = trajectory(np.minimum(np.arange(frames + 1) / fps, trajectory.duration), 0)
    paths = [viz.getViewerNodeName(g, pin.GeometryType.VISUAL) for g in visual.geometryObjects]
    animation = Animation(default_framerate=fps)
    for k, qk in enumerate(q):
        pin.forwardKinematics(model, data, qk)
        pin.updateGeometryPlacements(model, data, visual, gdata)
        frame = animation.at_frame(vis, k)
        for path, placement in zip(paths, gdata.oMg, strict=True):
            frame[path].set_transform(placement.homogeneous)
    viz.display(q[0])
    _aim_camera(vis, robot, q)
    _trail(vis, "planned", tip_path(robot, trajectory), 0xD62728)
    if initial is not None:
        _trail(vis, "initial", tip_path(robot, initial), 0x888888)
    vis.set_animation(animation, play=True, repetitions=1)


def _aim_camera(vis: meshcat.Visualizer, robot: Robot, q: NDArray[np.float64]) -> None:
    """Point the camera at the arm's base from far enough to see every link during the motion:
    along the plane's normal for a planar motion, from the front, right and above otherwise."""
    points = np.vstack(
        [
            np.array([m[:3, 3] for m in robot.link_placements(qk).values()])
            for qk in q[:: max(1, len(q) // 20)]
        ]
    )
    reach = max(float(np.max(np.linalg.norm(points, axis=1))), 0.2)
    axes = plane_axes(points)
    if axes is not None:  # planar: look along the normal (right × up), from the −y side
        direction = np.cross(axes[0], axes[1])
    else:
        direction = np.array([1.2, -1.0, 0.6]) / np.linalg.norm([1.2, -1.0, 0.6])
    eye = 2.2 * reach * direction
    # the camera lives in a frame rotated by +90° about x (three.js is y-up): p = (x, z, −y)
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [float(eye[0]), float(eye[2]), float(-eye[1])]
    )


def _trail(vis: meshcat.Visualizer, name: str, points: NDArray[np.float64], color: int) -> None:
    geometry = mg.PointsGeometry(points.T.astype(np.float32))
    vis["trails"][name].set_object(mg.Line(geometry, mg.LineBasicMaterial(color=color)))


def scene_html(
    robot: Robot, trajectory: Trajectory, initial: Trajectory | None = None, fps: float = 60.0
) -> str:
    """The animated scene of a motion as a standalone HTML page (no server, no network).

    Parameters
    ----------
    robot
        The arm.
    trajectory
        The motion to play.
    initial
        Another motion to show as a grey tip trail (e.g. the straight line's).
    fps
        Animation frames per second of motion time (it plays in real time).
    """
    recorder = _Recorder()
    _draw(meshcat.Visualizer(window=recorder), robot, trajectory, initial, fps)
    return recorder.html()


def export_html(result: PlanResult, path: str | Path, fps: float = 60.0) -> Path:
    """Write the plan's animation (and the straight line's tip trail) as a standalone HTML file.

    Returns
    -------
    Path
        The file written.
    """
    return write_atomically(path, plan_html(result, fps))


def plan_html(result: PlanResult, fps: float = 60.0) -> str:
    """:func:`scene_html` of a plan, with the straight line's tip trail."""
    return scene_html(result.robot, result.trajectory, result.initial.trajectory, fps)


class LiveViewer:
    """A meshcat server on 127.0.0.1 showing a plan; close it (or use ``with``) when done.

    The server runs in a child process that exits when this one closes it, exits, or dies (it
    watches its stdin, a pipe from here).

    Attributes
    ----------
    url
        Where the browser finds the viewer, ``http://127.0.0.1:PORT/static/``.
    visualizer
        The ``meshcat.Visualizer`` connected to the server, to add more to the scene.
    """

    def __init__(self, timeout: float = 30.0) -> None:
        # -P: do not put the working folder first on the child's path (it must import this nearopt)
        self._process = subprocess.Popen(
            [sys.executable, "-P", "-u", "-m", "nearopt.viz._meshcat_server"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(
            target=lambda: [lines.put(self._process.stdout.readline().strip()) for _ in range(2)],
            daemon=True,
        ).start()
        try:
            urls = dict(lines.get(timeout=timeout).split("=", 1) for _ in range(2))
            self.zmq_url, self.url = urls["zmq_url"], urls["web_url"]
        except (queue.Empty, ValueError, KeyError):
            self.close()
            raise NearoptError(
                f"the meshcat server did not start within {timeout:g} s "
                f"(exit code {self._process.poll()})"
            ) from None
        atexit.register(self.close)
        self.visualizer = meshcat.Visualizer(zmq_url=self.zmq_url)

    def close(self) -> None:
        """Stop the server and release its pipes and socket."""
        visualizer = getattr(self, "visualizer", None)
        if visualizer is not None:
            visualizer.window.zmq_socket.close(linger=0)
            self.visualizer = None
        if self._process.poll() is None:
            self._process.stdin.close()  # the server exits at the end of its stdin
            try:
                self._process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        for pipe in (self._process.stdin, self._process.stdout):
            pipe.close()
        atexit.unregister(self.close)

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def show(result: PlanResult, fps: float = 60.0, open_browser: bool = False) -> LiveViewer:
    """Play a plan in a browser through a meshcat server listening on 127.0.0.1 only.

    Parameters
    ----------
    result
        The plan.
    fps
        Animation frames per second of motion time.
    open_browser
        Also open the URL in the default browser.

    Returns
    -------
    LiveViewer
        The running server (``.url``); call ``close()`` to stop it.
    """
    viewer = LiveViewer()
    try:
        _draw(viewer.visualizer, result.robot, result.trajectory, result.initial.trajectory, fps)
    except BaseException:
        viewer.close()
        raise
    if open_browser:
        viewer.visualizer.open()
    return viewer
