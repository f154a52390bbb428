"""No import circle anywhere in the package, inside rooms too (issue 25, point 5): every import statement counts,
lazy ones inside functions included (only ``if TYPE_CHECKING:`` blocks are left out), and importing a module
counts as importing its parent packages, whose ``__init__`` runs first. tests/test_layout.py checks the rooms'
order; this checks every module against every other."""

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


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for child in node.body for n in ast.walk(child)}
    return skip


def imports_of(module: str, source: str, is_package: bool, known: set[str]) -> set[str]:
    """The package's modules that importing ``module`` runs: each import's target and the target's parents."""
    tree = ast.parse(source)
    skip = _type_checking_nodes(tree)
    here = module if is_package else module.rpartition(".")[0]
    targets = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            targets += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = here.split(".")[: len(here.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            targets += [base] + [f"{base}.{a.name}" for a in node.names]
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
    graph = {
        m: imports_of(m, (replace or {}).get(m) or p.read_text(), p.name == "__init__.py", known)
        for m, p in files.items()
    }
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
    assert circles(REPO / "selpres") == []


def test_the_check_finds_a_circle_through_a_lazy_import(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from pkg import c\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    assert circles(pkg) == [["pkg.a", "pkg.c", "pkg.sub.b"]]
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n")
    assert circles(pkg) == []
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
    (found,) = circles(REPO / "selpres", {package: heavy})  # one circle, through the sampler's own helpers too
    assert {package, "selpres.presentation.arguments", "selpres.presentation.sampler"} <= set(found)
