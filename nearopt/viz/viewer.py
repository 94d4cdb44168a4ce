"""Watch a plan in the browser: a meshcat animation, live (127.0.0.1 only) or as a standalone file.

The arm is drawn from its URDF visuals (meshes of example-robot-data as binary triangle meshes
with their materials' colours, primitives of the bundled arm), standing on a ground grid at its
base's height, z up as in the URDF; the camera frames every link position of the motion (along
the plane's normal for a planar arm, obliquely from above otherwise). The frames of meshcat's
Animation track (play / pause / scrub in the browser's "Animations" panel; it opens paused at
t = 0 in the start pose) are built from the kinematics, one per 1/fps s of the motion, in real
time. The tip's path is drawn as a trail, and the straight joint line the planner started from
as a grey one. The live and offline pages receive the same commands, so they look the same.

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
import functools
import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack
from meshcat.animation import Animation
from meshcat.servers.tree import SceneTree, find_node, walk
from pinocchio.visualize.meshcat_visualizer import loadPrimitive as load_primitive

from ..collision.scene import Box, Capsule, Cylinder, HalfSpace, Mesh, Scene, Sphere
from ..errors import ConfigurationError, NearoptError
from ..outputs import write_atomically
from ..planning import check_plan
from ..robot.kinematics import ToolPose
from .geometry import chain_points, plane_axes, target_poses, tip_path

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from ..planning import PlanResult, TaskResult
    from ..robot import Robot
    from ..trajectory import Trajectory

__all__ = [
    "export_html",
    "show",
    "LiveViewer",
    "scene_html",
    "plan_html",
    "scene_view",
    "SceneView",
    "mesh_parts",
    "draw_obstacles",
]

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
// the animation opens paused at t = 0 with its time slider live (meshcat starts its actions
// only on "play")
if (viewer.animator.actions.length) {{
  viewer.animator.play(); viewer.animator.pause(); viewer.animator.seek(0);
}}
</script>
</body>
</html>
"""


class SceneView(NamedTuple):
    """Where the scene is looked at from, in the robot's base frame (z up, as in the URDF).

    Attributes
    ----------
    centre
        Centre of the box holding every link position of the motion [m], shape (3,); the scene
        is shifted so that the camera orbits around it.
    radius
        Half the diagonal of that box [m] (at least 0.1).
    eye
        Camera position [m], shape (3,): along the normal of a planar arm's plane, from the
        front, right and above (30° elevation) otherwise, far enough for the box to fill the view.
    floor
        Height of the ground grid [m]: the base's (0), or below the lowest link if the arm
        reaches under its base.
    planar
        Whether every link moves in one plane.
    """

    centre: NDArray[np.float64]
    radius: float
    eye: NDArray[np.float64]
    floor: float
    planar: bool


def scene_view(robot: Robot, q: NDArray[np.float64]) -> SceneView:
    """The camera and floor for configurations ``q`` (shape (K, n)) of a motion."""
    points = np.vstack([chain_points(robot, qk) for qk in q[:: max(1, len(q) // 40)]])
    low, high = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (low + high)
    radius = max(0.5 * float(np.linalg.norm(high - low)), 0.1)
    axes = plane_axes(points)
    if axes is not None:  # planar: look along the normal (right × up), from the −y side
        direction = np.cross(axes[0], axes[1])
    else:
        direction = np.array(
            [
                np.cos(np.pi / 6) * np.cos(-np.pi / 5),
                np.cos(np.pi / 6) * np.sin(-np.pi / 5),
                np.sin(np.pi / 6),
            ]
        )
    # the sphere of the box fills the smaller side of meshcat's 75° field of view, 15 % margin
    distance = 1.15 * radius / np.sin(np.radians(75.0 / 2))
    floor = min(0.0, float(low[2]) - 0.05 * radius)
    return SceneView(centre, radius, centre + distance * direction, floor, axes is not None)


def _floor_grid(vis: meshcat.Visualizer, view: SceneView) -> None:
    """A square ground grid under the motion at the floor's height (lines every 0.1 m, or 0.5 m
    for motions wider than 4 m), replacing meshcat's own."""
    cell = 0.1 if view.radius < 2.0 else 0.5
    half = cell * np.ceil(1.5 * view.radius / cell)
    cx, cy = np.round(view.centre[:2] / cell) * cell
    ticks = np.arange(-half, half + 0.5 * cell, cell)
    ends = []
    for t in ticks:
        ends += [[cx + t, cy - half], [cx + t, cy + half], [cx - half, cy + t], [cx + half, cy + t]]
    xy = np.array(ends)
    points = np.column_stack([xy, np.full(len(xy), view.floor)]).T.astype(np.float32)
    vis["floor"].set_object(
        mg.LineSegments(mg.PointsGeometry(points), mg.LineBasicMaterial(color=0x6A6A6A))
    )


def _draw(
    vis: meshcat.Visualizer,
    robot: Robot,
    trajectory: Trajectory,
    initial: Trajectory | None,
    fps: float,
    scene: Scene | None = None,
    targets: tuple[ToolPose, ...] = (),
) -> None:
    """Load the arm, its animation (paused at t = 0), the trails, floor, obstacles, target
    frames and camera into meshcat."""
    if not (np.isfinite(fps) and fps > 0):
        raise ConfigurationError(f"fps must be a positive number, got {fps}")
    visual = robot.visual_model()
    paths = _load_visuals(vis, robot, visual)
    model, data = robot.model, robot.new_data()
    gdata = pin.GeometryData(visual)
    frames = int(np.ceil(trajectory.duration * fps - 1e-9))
    q = trajectory(np.minimum(np.arange(frames + 1) / fps, trajectory.duration), 0)

    def place(qk: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        pin.forwardKinematics(model, data, qk)
        pin.updateGeometryPlacements(model, data, visual, gdata)
        return [m.homogeneous for m in gdata.oMg]

    animation = Animation(default_framerate=fps)
    for k, qk in enumerate(q):
        frame = animation.at_frame(vis, k)
        placements = place(qk)
        for path, placement in zip(paths, placements, strict=True):
            frame[path].set_transform(placement)
            if k == 0:  # the start pose until played
                vis[path].set_transform(placement)
    view = scene_view(robot, q)
    _floor_grid(vis, view)
    if scene is not None:
        draw_obstacles(vis, scene, view)
    for k, target in enumerate(targets):  # a triad (x red, y green, z blue) per target pose
        node = vis["targets"][f"target{k}"]
        node.set_object(mg.triad(max(0.05, 0.1 * view.radius)))
        node.set_transform(target.placement().homogeneous)
    _trail(vis, "planned", tip_path(robot, trajectory), 0xD62728)
    if initial is not None:
        _trail(vis, "initial", tip_path(robot, initial), 0x888888)
    # meshcat's camera orbits the world origin: shift the scene so that it orbits the motion
    vis.set_transform(pin.SE3(np.eye(3), -view.centre).homogeneous)
    eye = view.eye - view.centre
    # the camera lives in a frame rotated by +90° about x (three.js is y-up): p = (x, z, −y)
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [float(eye[0]), float(eye[2]), float(-eye[1])]
    )
    vis["/Grid"].set_property("visible", False)
    vis["/Axes"].set_property("visible", False)
    vis.set_animation(animation, play=False, repetitions=1)


def _load_visuals(vis: meshcat.Visualizer, robot: Robot, visual: pin.GeometryModel) -> list[str]:
    """Every visual of the URDF under /meshcat/<robot>/visuals/<name>; returns the node paths.

    Mesh files (Collada, STL, OBJ) are read once with trimesh and sent as binary triangle
    meshes, one per colour of the file's materials, each vertex once per position and normal
    (normals computed by the browser): panda's page is 5.6 MB instead of 29 MB. Primitives go
    through Pinocchio's loader.
    """
    paths = []
    for g in visual.geometryObjects:
        path = f"{robot.name}/visuals/{g.name}"
        paths.append(path)
        if g.meshPath and Path(g.meshPath).is_file():
            for k, (vertices, faces, colour) in enumerate(
                mesh_parts(g.meshPath, tuple(float(x) for x in g.meshScale))
            ):
                vis[path][f"part{k}"].set_object(
                    mg.TriangularMeshGeometry(vertices, faces), _material(colour)
                )
        else:
            obj = load_primitive(g)
            if obj is None:
                raise NearoptError(f"the visual {g.name!r} of {robot.name} cannot be drawn")
            vis[path].set_object(obj, _material(g.meshColor))
    return paths


OBSTACLE_RGBA = (0.85, 0.55, 0.25, 0.75)
HALFSPACE_RGBA = (0.55, 0.6, 0.65, 0.35)


def draw_obstacles(vis: meshcat.Visualizer, scene: Scene, view: SceneView) -> None:
    """Every obstacle under /meshcat/obstacles/<name>, in place (translucent orange; a
    half-space as a translucent slab 1 cm thick whose top face is its boundary, as wide as the
    floor grid)."""
    for ob in scene.obstacles:
        node = vis["obstacles"][ob.name]
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = ob.rotation(), ob.position
        shape = ob.shape
        if isinstance(shape, Box):
            node.set_object(mg.Box(list(shape.size)), _material(OBSTACLE_RGBA))
        elif isinstance(shape, Sphere):
            node.set_object(mg.Sphere(shape.radius), _material(OBSTACLE_RGBA))
        elif isinstance(shape, Cylinder | Capsule):  # meshcat's cylinders run along y
            along_z = pin.utils.rotate("x", np.pi / 2)
            body = node["body"]
            body.set_object(mg.Cylinder(shape.length, shape.radius), _material(OBSTACLE_RGBA))
            body.set_transform(pin.SE3(along_z, np.zeros(3)).homogeneous)
            if isinstance(shape, Capsule):
                for k, z in enumerate((-0.5 * shape.length, 0.5 * shape.length)):
                    node[f"end{k}"].set_object(mg.Sphere(shape.radius), _material(OBSTACLE_RGBA))
                    node[f"end{k}"].set_transform(
                        pin.SE3(np.eye(3), np.array([0, 0, z])).homogeneous
                    )
        elif isinstance(shape, HalfSpace):
            n = np.asarray(shape.normal)
            side = 3.0 * view.radius
            thickness = 0.01
            # the slab's z axis along n, its top face on n·x = d, centred under the motion
            z = n
            x = np.cross([0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0], z)
            x /= np.linalg.norm(x)
            frame = np.column_stack([x, np.cross(z, x), z])
            local = ob.rotation().T @ (view.centre - np.asarray(ob.position))  # in its frame
            foot = local - (local @ n - shape.offset) * n - 0.5 * thickness * n
            slab = np.eye(4)
            slab[:3, :3], slab[:3, 3] = frame, foot
            node["slab"].set_object(mg.Box([side, side, thickness]), _material(HALFSPACE_RGBA))
            node["slab"].set_transform(slab)
        elif isinstance(shape, Mesh):
            for k, (vertices, faces, _) in enumerate(
                mesh_parts(str(shape.path), (shape.scale,) * 3)
            ):
                node[f"part{k}"].set_object(
                    mg.TriangularMeshGeometry(vertices, faces), _material(OBSTACLE_RGBA)
                )
        node.set_transform(pose)


def _material(rgba: ArrayLike) -> mg.MeshPhongMaterial:
    """A Phong material of colour RGBA in [0, 1] (transparent if alpha < 1)."""
    material = mg.MeshPhongMaterial(color=_colour_int(np.asarray(rgba)[:3]))
    if float(rgba[3]) < 1.0:
        material.transparent, material.opacity = True, float(rgba[3])
    return material


def _trail(vis: meshcat.Visualizer, name: str, points: NDArray[np.float64], color: int) -> None:
    geometry = mg.PointsGeometry(points.T.astype(np.float32))
    vis["trails"][name].set_object(mg.Line(geometry, mg.LineBasicMaterial(color=color)))


def _colour_int(rgb: ArrayLike) -> int:
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgb)
    return (r << 16) | (g << 8) | b


@functools.lru_cache(maxsize=256)
def mesh_parts(
    path: str, scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> tuple[tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float64]], ...]:
    """A mesh file as triangle meshes, one per colour: (vertices [m] (V, 3), faces (F, 3),
    RGBA in [0, 1]), in the file's frame scaled by ``scale`` (the URDF's ``<mesh scale>``).

    Raises
    ------
    NearoptError
        If the file cannot be read as a mesh.
    """
    import trimesh

    try:
        scene = trimesh.load(path, force="scene", process=False)
    except Exception as exc:  # trimesh raises whatever its readers raise
        raise NearoptError(f"cannot read the mesh {path}: {exc}") from None
    by_colour: dict[tuple[int, ...], list[tuple[NDArray, NDArray]]] = {}
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        mesh = scene.geometry[name]
        if not hasattr(mesh, "faces") or len(mesh.faces) == 0:
            continue
        vertices = (trimesh.transform_points(mesh.vertices, transform) * np.asarray(scale)).astype(
            np.float32
        )
        # files repeat a vertex for every face around it: keep one per position and normal
        # direction (to about 15°), so that the browser's normals keep the sharp edges
        key = np.hstack([vertices, np.round(4.0 * mesh.vertex_normals).astype(np.float32)])
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        vertices, faces = vertices[first], inverse.reshape(-1)[np.asarray(mesh.faces)]
        visual = mesh.visual
        colour = getattr(visual, "main_color", None)
        if colour is None and getattr(visual, "material", None) is not None:
            colour = visual.material.main_color
        rgba = tuple(int(c) for c in (colour if colour is not None else (230, 230, 230, 255)))
        by_colour.setdefault(rgba, []).append((vertices, faces))
    parts = []
    for key, meshes in by_colour.items():
        offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
        vertices = np.vstack([v for v, _ in meshes]).astype(np.float32)
        faces = np.vstack([f + o for (_, f), o in zip(meshes, offsets, strict=True)])
        parts.append((vertices, faces.astype(np.uint32), np.array(key, dtype=float) / 255.0))
    if not parts:
        raise NearoptError(f"the mesh {path} has no triangles")
    return tuple(parts)


def scene_html(
    robot: Robot,
    trajectory: Trajectory,
    initial: Trajectory | None = None,
    fps: float = 60.0,
    scene: Scene | None = None,
    targets: tuple[ToolPose, ...] = (),
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
    scene
        Obstacles to draw.
    targets
        Tool poses to mark with a triad (x red, y green, z blue).
    """
    recorder = _Recorder()
    _draw(meshcat.Visualizer(window=recorder), robot, trajectory, initial, fps, scene, targets)
    return recorder.html()


def export_html(result: PlanResult | TaskResult, path: str | Path, fps: float = 60.0) -> Path:
    """Write the plan's animation (and the straight line's tip trail) as a standalone HTML file.

    Returns
    -------
    Path
        The file written.
    """
    return write_atomically(path, plan_html(result, fps))


def plan_html(result: PlanResult | TaskResult, fps: float = 60.0) -> str:
    """:func:`scene_html` of a plan, with the first path's tip trail and the obstacles."""
    check_plan(result)
    return scene_html(
        result.robot,
        result.trajectory,
        result.initial_trajectory,
        fps,
        _scene_of(result),
        target_poses(result),
    )


def _scene_of(result: PlanResult | TaskResult) -> Scene | None:
    return None if result.collisions is None else result.collisions.scene


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


def show(
    result: PlanResult | TaskResult, fps: float = 60.0, open_browser: bool = False
) -> LiveViewer:
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
    check_plan(result)
    viewer = LiveViewer()
    try:
        _draw(
            viewer.visualizer,
            result.robot,
            result.trajectory,
            result.initial_trajectory,
            fps,
            _scene_of(result),
            target_poses(result),
        )
    except BaseException:
        viewer.close()
        raise
    if open_browser:
        viewer.visualizer.open()
    return viewer
