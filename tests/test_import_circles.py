"""No import circle anywhere, inside rooms too (issue 25 point 5, issue 37 point 6): every import statement counts,
lazy ones inside functions included and those under ``if TYPE_CHECKING:`` too (a circle a type checker follows is a
circle of the design, whatever runs), and importing a module counts as importing its parent packages, whose
``__init__`` runs first. Checked in the library and in the studies' and benchmarks' packages beside it.
tests/test_layout.py checks the rooms' order and that the library never reaches the studies; this checks every
module against every other."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from conftest import REPO


def module_files(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for the package at ``root`` (a package is named by its ``__init__``)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def bound_names(tree: ast.Module, imported: bool = True) -> set[str]:
    """The names a module binds at its top level: its definitions and assignments, and (``imported``) its imports."""
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif imported and isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return out


def lazy_exports(trees: dict[str, ast.Module], packages: set[str]) -> dict[str, dict[str, set[str]]]:
    """package -> name -> the package's modules that define it, for the names a package serves lazily (PEP 562: its
    ``__init__`` defines ``__getattr__`` and does not bind the name itself, as ``selpres`` and ``selpres.report`` do):
    ``from pkg import Name`` runs the module behind it."""
    out: dict[str, dict[str, set[str]]] = {}
    for pkg in packages:
        if "__getattr__" not in bound_names(trees[pkg]):
            continue
        own = bound_names(trees[pkg])
        for m, tree in trees.items():
            if m.startswith(pkg + ".") and m != pkg:
                for name in bound_names(tree, imported=False) - own:
                    out.setdefault(pkg, {}).setdefault(name, set()).add(m)
    return out


def imports_of(
    module: str, source: str, is_package: bool, known: set[str], lazy: dict[str, dict[str, set[str]]] | None = None
) -> set[str]:
    """The package's modules that importing ``module`` runs: each import's target and the target's parents (and,
    for a name a package serves lazily, the module that defines it)."""
    here = module if is_package else module.rpartition(".")[0]
    targets = []
    for node in ast.walk(ast.parse(source)):  # TYPE_CHECKING blocks included
        if isinstance(node, ast.Import):
            targets += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = here.split(".")[: len(here.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            targets += [base] + [f"{base}.{a.name}" for a in node.names]
            for a in node.names:
                if f"{base}.{a.name}" not in known:
                    targets += sorted((lazy or {}).get(base, {}).get(a.name, ()))
    out = set()
    for t in targets:
        while t and t not in known:  # from pkg import name: name is a module of pkg or an attribute of it
            t = t.rpartition(".")[0]
        while t:  # the module and every package above it run
            if t != module and not module.startswith(t + "."):  # a module's own packages ran before it
                out.add(t)
            t = t.rpartition(".")[0]
    return out & known


def circles(root: Path, replace: dict[str, str] | None = None) -> list[list[str]]:
    """The import circles (strongly connected components of more than one module) of the package at ``root``;
    ``replace``: module -> source to check in place of its file."""
    files = module_files(root)
    known = set(files)
    sources = {m: (replace or {}).get(m) or p.read_text() for m, p in files.items()}
    trees = {m: ast.parse(src) for m, src in sources.items()}
    lazy = lazy_exports(trees, {m for m, p in files.items() if p.name == "__init__.py"})
    graph = {m: imports_of(m, sources[m], p.name == "__init__.py", known, lazy) for m, p in files.items()}
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
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
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle_in_the_package():
    """No circle, imports for types only counted (presentation/selection.py and orders/_stagewise.py once named each
    other for types; the staged selector, issue 37 point 1, ended it)."""
    assert circles(REPO / "selpres") == []


@pytest.mark.parametrize("package", ["selpres_studies", "selpres_bench", "hydra_plugins"])
def test_no_import_circle_beside_the_package(package):
    root = REPO / ("studies" if package.startswith("selpres_") else "") / package
    assert circles(root) == []


def test_the_check_finds_a_circle_through_a_lazy_import(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from pkg import c\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    assert circles(pkg) == [["pkg.a", "pkg.c", "pkg.sub.b"]]
    # an import for types only closes the circle too (issue 37: the report's build -> context -> build was one)
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n")
    assert circles(pkg) == [["pkg.a", "pkg.c", "pkg.sub.b"]]
    # a package's __init__ runs when any of its modules is imported: a circle through it counts too
    (pkg / "sub" / "__init__.py").write_text("from pkg import c\n")
    (pkg / "sub" / "b.py").write_text("")
    (pkg / "c.py").write_text("from pkg.sub.b import f\n")
    assert circles(pkg) == [["pkg.c", "pkg.sub"]]


@pytest.mark.parametrize("package", ["selpres.presentation.pruning", "selpres.presentation.orders"])
def test_the_name_lists_stay_light(package):
    """The circle issue 25 removed (arguments -> pruning -> selection -> sampler -> arguments) comes back if a
    registry package that the arguments read (the pruning policies', the orders') imports the sampler: the check
    sees it. (``selection`` names the sampler for its types only, so a job's pruning or selection is no path.)"""
    init = REPO / (package.replace(".", "/") + "/__init__.py")
    heavy = init.read_text() + "\n\ndef samplers():\n    from selpres.presentation.sampler import epoch_orders\n"
    (found,) = [c for c in circles(REPO / "selpres", {package: heavy}) if package in c]  # through the sampler too
    assert {package, "selpres.presentation.arguments", "selpres.presentation.sampler"} <= set(found)
