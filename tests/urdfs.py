"""Small URDF files for tests, varied one feature at a time."""

from __future__ import annotations

from pathlib import Path

LINK = """<link name="{name}"><inertial><origin xyz="0 0 0.1"/><mass value="1"/>
<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.001"/></inertial></link>"""
BARE_LINK = '<link name="{name}"/>'
JOINT = """<joint name="{name}" type="{type}"><parent link="{parent}"/><child link="{child}"/>
<origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>{limit}{extra}</joint>"""
LIMIT = '<limit effort="5" velocity="2" lower="-3" upper="3"/>'


def write_urdf(
    tmp_path: Path,
    *,
    types: tuple[str, str] = ("revolute", "revolute"),
    limits: tuple[str, str] = (LIMIT, LIMIT),
    extra: tuple[str, str] = ("", ""),
    inertial: bool = True,
) -> Path:
    """A two-joint chain base → a → b, varied one feature at a time."""
    link = LINK if inertial else BARE_LINK
    parts = ['<robot name="chain">', BARE_LINK.format(name="base"), link.format(name="a")]
    parts.append(link.format(name="b"))
    for k, (parent, child) in enumerate((("base", "a"), ("a", "b"))):
        parts.append(
            JOINT.format(
                name=f"j{k + 1}",
                type=types[k],
                parent=parent,
                child=child,
                limit=limits[k],
                extra=extra[k],
            )
        )
    parts.append("</robot>")
    path = tmp_path / "chain.urdf"
    path.write_text("\n".join(parts))
    return path


def erd_urdf(relative: str) -> Path:
    """A URDF of example-robot-data, by its path below the package's ``robots/`` folder."""
    from nearopt.catalog import package_dirs

    return package_dirs()[0] / "example-robot-data" / "robots" / relative
