"""solvers/ and db/ never load textual or station (checked in a fresh interpreter)."""

from __future__ import annotations

import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules(package: str) -> list[str]:
    pkg_dir = ROOT / package
    names = [package]
    for info in pkgutil.walk_packages([str(pkg_dir)], prefix=f"{package}."):
        names.append(info.name)
    return names


@pytest.mark.parametrize("package", ["solvers", "db"])
def test_headless_packages_do_not_import_ui_or_app(package):
    code = (
        "import importlib, sys\n"
        f"for name in {_modules(package)!r}:\n"
        "    importlib.import_module(name)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in {'textual', 'station', 'serial'})\n"
        f"bad += sorted(m for m in sys.modules if {package!r} == 'solvers' and m.split('.')[0] in {{'sqlite_utils', 'db'}})\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"{package} pulled in: {out.stdout.strip()}"


# ---------------------------------------------------------------- the import graph, read from the source

PACKAGES = sorted(p.parent.name for p in ROOT.glob("*/__init__.py"))
# What each layer must never import (top-level module names, or dotted prefixes);
# function-level imports count too. A new package must say where it stands.
NEVER = {
    "solvers": ("station", "db", "textual", "serial", "sqlite_utils"),
    "db": ("station", "textual", "serial"),
    "station": (),
}
# The UI-free procedure logic (the TUI is a thin view over it).
NEVER_UI_FREE = ("textual", "rich", "station.app", "station.screens", "station.widgets")
NUMPY_FREE = (
    "station.procedures.registry",
    "station.procedures.contract",
    "station.formatting",
    "solvers.jsonable",
    "db.params",
)


def _imports(path: Path) -> list[tuple[int, str]]:
    import ast

    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out += [(node.lineno, node.module)] + [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def _hits(name: str, banned) -> bool:
    return any(name == b or name.startswith(b + ".") for b in banned)


def test_every_package_has_a_layer():
    assert set(PACKAGES) == set(NEVER), "a new top-level package: add its rule to NEVER"


@pytest.mark.parametrize("package", PACKAGES)
def test_imports_respect_the_layers(package):
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT)
        banned = NEVER[package]
        if rel.parts[:2] == ("station", "procedures"):
            banned = banned + NEVER_UI_FREE
        bad += [f"{rel}:{line}: {name}" for line, name in _imports(path) if _hits(name, banned)]
    assert not bad, "\n".join(bad)


def test_the_lists_load_without_numpy():
    """The registry, the contract, the formatter and the JSON sanitizer start fast."""
    code = (
        "import sys\n"
        + "".join(f"import {m}\n" for m in NUMPY_FREE)
        + "print(','.join(m for m in ('numpy', 'textual') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_no_module_imports_another_modules_private_name():
    """``from x import _name`` or ``x._name`` across modules: a private name is its module's
    business (dunders like __version__ are public)."""
    import ast

    ours = tuple(PACKAGES)
    bad = []
    for path in sorted(p for d in PACKAGES + ["benchmarks"] for p in (ROOT / d).rglob("*.py")):
        rel = path.relative_to(ROOT)
        here = ".".join(rel.with_suffix("").parts)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        modules = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ours:
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__") and node.module != here:
                        bad.append(f"{rel}:{node.lineno}: from {node.module} import {a.name}")
                    modules[a.asname or a.name] = node.module
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] in ours:
                        modules[a.asname or a.name.split(".")[0]] = a.name
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in modules
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                bad.append(f"{rel}:{node.lineno}: {node.value.id}.{node.attr}")
    assert not bad, "\n".join(bad)


# ---------------------------------------------------------------- no import circles


def _module_graph(package: str) -> dict[str, set[str]]:
    """Module → the modules of ``package`` it imports anywhere in its source (function-level
    and relative imports included); ``from a.b import c`` counts as ``a.b.c`` when that is a
    module, else as ``a.b``."""
    import ast

    files = {".".join(p.relative_to(ROOT).with_suffix("").parts): p for p in (ROOT / package).rglob("*.py")}
    files = {(m[: -len(".__init__")] if m.endswith(".__init__") else m): p for m, p in files.items()}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for here, path in files.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = here.split(".") if is_pkg else here.split(".")[:-1]
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join(parts + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            for t in targets:
                while t and t not in files:  # `import a.b.c` of a name inside a module
                    t = t.rpartition(".")[0]
                if t and t != here:
                    graph[here].add(t)
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_circle_finder_finds_a_circle_hidden_in_a_function(tmp_path, monkeypatch):
    """The check below can fail: two modules importing each other, one inside a function."""
    pkg = tmp_path / "toypkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from toypkg.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from .. import a\n    return a\n")
    (pkg / "c.py").write_text("import toypkg.a\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    graph = _module_graph("toypkg")
    assert graph["toypkg.sub.b"] == {"toypkg.a"} and graph["toypkg.c"] == {"toypkg.a"}
    assert _circles(graph) == [["toypkg.a", "toypkg.sub.b"]]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circles(package):
    """No two modules import each other, directly or round a loop, even inside functions
    (a circle hidden in a function still ties the two modules' changes together)."""
    circles = _circles(_module_graph(package))
    assert not circles, "\n".join(" <-> ".join(c) for c in circles)
