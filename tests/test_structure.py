"""The package's structure, read from its code with ``ast``: a straight line of layers.

Every import of a ``nearopt`` module by another (at the top or inside a function) is an arrow;
the test holds: no cycle, no private name (``_x``) imported from another module, argparse only
in the command line, nothing but the command line (and ``python -m``) importing it, and no function
longer than 100 lines (docstrings left out). Run as a script, it prints the graph's size and the
functions over 100 lines.

    python tests/test_structure.py
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "nearopt"


@dataclass
class Structure:
    """Modules, their arrows and what crosses them."""

    modules: dict[str, Path] = field(default_factory=dict)
    arrows: dict[str, set[str]] = field(default_factory=dict)
    private: list[tuple[str, str, str]] = field(default_factory=list)  # importer, module, name
    argparse: set[str] = field(default_factory=set)
    long_functions: list[tuple[str, str, int]] = field(default_factory=list)

    def cycles(self) -> list[list[str]]:
        """The strongly connected components with more than one module (Tarjan)."""
        index: dict[str, int] = {}
        low: dict[str, int] = {}
        stack: list[str] = []
        on_stack: set[str] = set()
        found: list[list[str]] = []

        def visit(v: str) -> None:
            index[v] = low[v] = len(index)
            stack.append(v)
            on_stack.add(v)
            for w in sorted(self.arrows[v]):
                if w not in index:
                    visit(w)
                    low[v] = min(low[v], low[w])
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    found.append(sorted(component))

        for v in sorted(self.modules):
            if v not in index:
                visit(v)
        return found


def read_structure(package: Path = PACKAGE) -> Structure:
    out = Structure()
    packages = set()
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
            packages.add(".".join(parts))
        out.modules[".".join(parts)] = path
    for name, path in out.modules.items():
        home = name if name in packages else name.rpartition(".")[0]
        arrows: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == "argparse":
                        out.argparse.add(name)
                    if alias.name.split(".")[0] == "nearopt" and alias.name in out.modules:
                        arrows.add(alias.name)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = home.split(".")[: len(home.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target == "argparse":
                    out.argparse.add(name)
                if target.split(".")[0] != "nearopt":
                    continue
                for alias in node.names:
                    submodule = f"{target}.{alias.name}"
                    if submodule in out.modules:
                        arrows.add(submodule)
                        continue
                    arrows.add(target)
                    if alias.name.startswith("_") and target != name:
                        out.private.append((name, target, alias.name))
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = _length(node)
                if length > 100:
                    out.long_functions.append((name, node.name, length))
        arrows.discard(name)
        out.arrows[name] = arrows
    return out


def _length(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """A function's lines, from ``def`` to its end, its docstring left out."""
    length = node.end_lineno - node.lineno + 1  # type: ignore[operator]
    first = node.body[0]
    if (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        length -= first.end_lineno - first.lineno + 1  # type: ignore[operator]
    return length


def test_the_layers_have_no_cycle() -> None:
    structure = read_structure()
    assert len(structure.modules) > 30  # the package was read
    assert structure.cycles() == []


def test_no_private_name_crosses_a_module() -> None:
    assert read_structure().private == []


def test_no_function_is_longer_than_100_lines() -> None:
    """Docstrings left out; the reader's self-test below shows a long function is seen."""
    assert read_structure().long_functions == []


def test_only_the_command_line_knows_argparse() -> None:
    structure = read_structure()
    assert structure.argparse == {"nearopt.cli"}
    importers = {m for m, arrows in structure.arrows.items() if "nearopt.cli" in arrows}
    assert importers <= {"nearopt.__main__"}, importers


def test_only_the_robot_makes_pinocchio_data() -> None:
    """Pinocchio's work spaces (pin.Data, one per caller and thread; a pool of model and data
    for its batched algorithms) come from Robot.new_data and Robot.new_pool."""
    for maker in ("createData(", "ModelPool("):
        makers = {
            name
            for name, path in read_structure().modules.items()
            if maker in path.read_text(encoding="utf-8")
        }
        assert makers == {"nearopt.robot.dynamics"}, (maker, makers)


def test_the_reader_sees_a_cycle_and_a_private_import(tmp_path: Path) -> None:
    """The checks can fail: a package with a cycle and a private import is reported."""
    package = tmp_path / "nearopt"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from .sub.b import _hidden\n")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "b.py").write_text(
        "def f():\n    from ..a import x\n\n\ndef g():\n" + "    x = 1\n" * 100
    )
    structure = read_structure(package)
    assert structure.cycles() == [["nearopt.a", "nearopt.sub.b"]]
    assert structure.private == [("nearopt.a", "nearopt.sub.b", "_hidden")]
    assert structure.long_functions == [("nearopt.sub.b", "g", 101)]


if __name__ == "__main__":
    found = read_structure()
    print(
        f"{len(found.modules)} modules, {sum(map(len, found.arrows.values()))} arrows, "
        f"cycles: {found.cycles() or 'none'}, private imports: {found.private or 'none'}"
    )
    for module, function, length in sorted(found.long_functions, key=lambda x: -x[2]):
        print(f"  {module}.{function}: {length} lines")
