"""Seeing a plan: the figures (matplotlib) and the 3-D scene (meshcat), side by side.

* :mod:`nearopt.viz.figures` — torques, workspace paths and the iteration history as figures;
* :mod:`nearopt.viz.viewer` — the animated scene, live (:func:`show`) or as an offline page
  (:func:`export_html`);
* :mod:`nearopt.viz.geometry` — what both draw: the tip's path, the links' centre lines, the plane
  of a planar arm.

matplotlib and meshcat are imported only when a figure or a scene is made.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_WHERE = {
    "plot_torques": "figures",
    "plot_speeds": "figures",
    "plot_accelerations": "figures",
    "plot_workspace": "figures",
    "plot_history": "figures",
    "render_figures": "figures",
    "save_figures": "figures",
    "export_html": "viewer",
    "plan_html": "viewer",
    "scene_html": "viewer",
    "show": "viewer",
    "LiveViewer": "viewer",
    "plane_axes": "geometry",
    "tip_path": "geometry",
    "chain_points": "geometry",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:  # noqa: ANN401 - whatever the submodule defines
    if name not in _WHERE:
        raise AttributeError(f"module 'nearopt.viz' has no attribute {name!r}")
    return getattr(import_module(f".{_WHERE[name]}", __name__), name)
