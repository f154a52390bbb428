"""The package's rooms follow the flow arm -> data -> presentation -> engines -> run -> report: a module imports only
its own room, rooms before it and the foundation (errors, registry, seeding, storage, native, and patterns, the data
types every room shares) — lazy imports inside functions included. Also: every room says what it owns and may
import, no module outgrows ~450 lines, and the library stands apart from its studies and benchmarks (the sibling
packages of studies/): nothing in it imports or names them (the report is given its study plug-ins), and the
studies use only the public API, ``selpres`` and the report's blocks ``selpres.report``, as a user's study would."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import yaml

from conftest import REPO

FOUNDATION = (
    "selpres.errors",
    "selpres.registry",
    "selpres.seeding",
    "selpres.storage",
    "selpres.native",
    "selpres.patterns",
)
ROOMS = ("arms", "data", "presentation", "engines", "run", "report")
SIBLINGS = ("selpres_studies", "selpres_bench")  # studies/: apart from the library, not in its wheel
MAX_LINES = 450
# Rooms that get specs, not configs (issue 25): only selpres.run reads the composed config, so these import neither
# omegaconf nor hydra (nor a selpres.run enum: the flow check above refuses any import of run).
SPEC_ROOMS = ("arms", "data", "presentation", "engines", "native")
CONFIG_PACKAGES = ("omegaconf", "hydra")


def room_rank(module: str) -> int:
    """0 for the foundation, 1.. for the rooms in flow order, len(ROOMS) + 1 for the public API and plugins."""
    if module.startswith(FOUNDATION) and (module + ".").split(".")[1] in {m.split(".")[1] for m in FOUNDATION}:
        return 0
    parts = module.split(".")
    if parts[0] == "selpres" and len(parts) > 1 and parts[1] in ROOMS:
        return 1 + ROOMS.index(parts[1])
    return len(ROOMS) + 1  # selpres itself (the public API), hydra_plugins


def imported_modules(source: str, package: str, roots: tuple[str, ...] = ("selpres",)) -> list[tuple[int, str]]:
    """(line, module) for every import in ``source`` of the packages ``roots`` (``from selpres import x`` ->
    selpres.x when x is a room or module of the package, else selpres itself: the public API)."""
    names = {p.stem for p in (REPO / "selpres").iterdir() if p.suffix == ".py" or p.is_dir()}
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] in roots]
        elif isinstance(node, ast.ImportFrom) and node.module:
            mod = node.module
            if node.level:  # relative: resolve against the importing package
                mod = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + [mod])
            if mod == "selpres" and "selpres" in roots:
                out += [(node.lineno, f"selpres.{a.name}" if a.name in names else "selpres") for a in node.names]
            elif mod.split(".")[0] in roots:
                out.append((node.lineno, mod))
    return out


def violations(path: Path, module: str, source: str) -> list[str]:
    own = room_rank(module)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    return [
        f"{path.relative_to(REPO)}:{line} imports {target} (a room after it in the flow)"
        for line, target in imported_modules(source, package)
        if room_rank(target) > own
    ]


def modules():
    for path in sorted([*(REPO / "selpres").rglob("*.py"), *(REPO / "hydra_plugins").rglob("*.py")]):
        rel = path.relative_to(REPO).with_suffix("")
        parts = list(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        yield path, ".".join(parts)


def test_imports_run_one_way():
    found = [v for path, module in modules() for v in violations(path, module, path.read_text())]
    assert found == []


def test_the_check_sees_a_backward_import_even_inside_a_function():
    src = "def f():\n    from selpres.run.train import train\n    from selpres.presentation import sampler\n"
    assert violations(REPO / "selpres/data/task.py", "selpres.data.task", src) == [
        "selpres/data/task.py:2 imports selpres.run.train (a room after it in the flow)",
        "selpres/data/task.py:3 imports selpres.presentation (a room after it in the flow)",
    ]
    # the foundation may not import a room, and no room may import the public API
    assert violations(REPO / "selpres/storage.py", "selpres.storage", "import selpres.arms.serial\n")
    assert violations(REPO / "selpres/run/cli.py", "selpres.run.cli", "from selpres import SelectivePresentation\n")
    assert not violations(REPO / "selpres/run/cli.py", "selpres.run.cli", "from selpres import native, errors\n")


def test_every_room_says_what_it_owns_and_may_import():
    for room in (*ROOMS, "native"):
        doc = ast.get_docstring(ast.parse((REPO / "selpres" / room / "__init__.py").read_text())) or ""
        assert "May import" in doc or "may import" in doc, room


def test_no_module_over_450_lines():
    paths = [p for p, _ in (*modules(), *sibling_modules())]
    long = {str(p.relative_to(REPO)): n for p in paths if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def sibling_modules():
    for path in sorted((REPO / "studies").rglob("*.py")):
        rel = path.relative_to(REPO / "studies").with_suffix("")
        parts = list(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        if parts and parts[0] in SIBLINGS:
            yield path, ".".join(parts)


def test_nothing_in_the_library_imports_or_names_the_studies():
    """No run-time loop: no module of the library imports the studies or the benchmarks, nor holds their names in
    its code (so it cannot load them by name either); the report is given its study plug-ins."""
    names = set(SIBLINGS)
    found = [
        f"{path.relative_to(REPO)}:{line} imports {target}"
        for path, module in modules()
        for line, target in imported_modules(path.read_text(), module, roots=SIBLINGS)
    ]
    found += [
        f"{path.relative_to(REPO)}:{line} names {name}"
        for path, _ in modules()
        for line, name in named_in_code(path.read_text(), names)
    ]
    assert found == []
    # and the checks see them
    assert imported_modules("from selpres_studies import modern\n", "selpres.report", SIBLINGS) == [
        (1, "selpres_studies")
    ]
    assert named_in_code('STUDIES = "selpres_studies"\n', names) == [(1, "selpres_studies")]


def public_api_violations(path: Path, module: str, source: str) -> list[str]:
    """The imports of selpres in ``source`` that are not its public API: ``selpres``'s and ``selpres.report``'s
    ``__all__``."""
    import selpres
    import selpres.report

    api = {"selpres": set(selpres.__all__), "selpres.report": set(selpres.report.__all__)}
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "selpres"]
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "selpres":
            if node.module in api:
                out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names if a.name not in api[node.module]]
            else:
                out.append((node.lineno, node.module))
    return [f"{path.relative_to(REPO)}:{line} imports {what} (not the public API)" for line, what in out]


def test_the_studies_use_only_the_public_api():
    """A study is written as a user writes one: from ``selpres`` and the report's blocks (``selpres.report``) only.
    The benchmarks time the library's insides, as the tests do, and are not held to this."""
    found = [
        v
        for path, module in sibling_modules()
        if module.startswith("selpres_studies")
        for v in public_api_violations(path, module, path.read_text())
    ]
    assert found == []
    # and the check sees an internal module, a name outside the API, and a plain import of a room
    where = REPO / "studies/selpres_studies/x.py"
    src = "from selpres.report.groups import Group\nfrom selpres.report import table, jobs\nimport selpres.run\n"
    assert public_api_violations(where, "selpres_studies.x", src) == [
        "studies/selpres_studies/x.py:1 imports selpres.report.groups (not the public API)",
        "studies/selpres_studies/x.py:2 imports selpres.report.jobs (not the public API)",
        "studies/selpres_studies/x.py:3 imports selpres.run (not the public API)",
    ]
    assert public_api_violations(where, "selpres_studies.x", "from selpres.report import Group, table\n") == []


def test_the_core_and_the_report_import_without_the_studies():
    """import selpres, the core's rooms and the report's blocks load no study or benchmark module."""
    code = (
        "import sys, selpres, selpres.arms, selpres.data, selpres.presentation, selpres.engines, selpres.run.train, "
        "selpres.report, selpres.report.build, selpres.report.__main__, selpres.report.plugins; "
        "print(sorted(m for m in sys.modules if m.startswith(('selpres_studies', 'selpres_bench'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]"]


def design_names() -> set[str]:
    """The methods and arms the studies' designs name (``studies/selpres_studies/*.yaml``: roles, rows' order, the
    methods a paper lacks, arms' display names)."""
    names: set[str] = set()
    for path in (REPO / "studies" / "selpres_studies").glob("*.yaml"):
        d = yaml.safe_load(path.read_text())
        names |= {d[k] for k in ("reference", "baseline", "partner") if isinstance(d.get(k), str)}
        names |= {*(d.get("order") or []), *(d.get("not_in_paper") or {}), *(d.get("arms") or {})}
    return names


def named_in_code(source: str, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) for every one of ``names`` a string in ``source``'s code holds as a word (f-strings included;
    docstrings are prose and left out)."""
    tree = ast.parse(source)
    scopes = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    docs = {
        id(n.body[0].value)
        for n in ast.walk(tree)
        if isinstance(n, scopes)
        and n.body
        and isinstance(n.body[0], ast.Expr)
        and isinstance(n.body[0].value, ast.Constant)
    }
    return [
        (node.lineno, name)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
        for name in sorted(names)
        if re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", node.value)
    ]


def test_the_shared_report_code_names_no_method_or_arm():
    """Issue 25, point 6: which method is a verdict's reference, which runs are targets and the order of rows are a
    study's (its design, studies/selpres_studies/<name>.yaml), so the report's code holds none of the names the designs
    use; a block takes them as arguments."""
    names = design_names()
    assert {"conventional", "selective", "matched", "random_growth", "infobatch", "two_link"} <= names
    found = [
        f"{path.relative_to(REPO)}:{line} names {name}"
        for path, module in modules()
        if module.startswith("selpres.report")
        for line, name in named_in_code(path.read_text(), names)
    ]
    assert found == []
    # and the check sees one, in a constant or an f-string, but not in a docstring or inside a longer name
    code = '"""selective is prose."""\nREF = "selective"\nx = f"{REF} vs matched"\ny = "selective_backprop"\n'
    assert named_in_code(code, {"selective", "matched"}) == [(2, "selective"), (3, "matched")]


def config_imports(source: str) -> list[tuple[int, str]]:
    """(line, module) for every omegaconf/hydra import in ``source``, lazy imports inside functions included."""
    out = []
    for node in ast.walk(ast.parse(source)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
        out += [(node.lineno, n) for n in names if n.split(".")[0] in CONFIG_PACKAGES]
    return out


def spec_room_violations(rooms: tuple[str, ...]) -> list[str]:
    return [
        f"{path.relative_to(REPO)}:{line} imports {name} (this room gets specs from selpres.run, not configs)"
        for path, module in modules()
        if module.split(".")[1:2] and module.split(".")[1] in rooms
        for line, name in config_imports(path.read_text())
    ]


def test_rooms_below_run_get_specs_not_configs():
    assert spec_room_violations(SPEC_ROOMS) == []


def test_the_spec_check_sees_a_config_import_even_inside_a_function():
    src = "import os\ndef f(cfg):\n    from omegaconf import OmegaConf\n    import hydra.utils\n"
    assert config_imports(src) == [(3, "omegaconf"), (4, "hydra.utils")]
    # and it looks in the rooms it is given: run reads the composed config by design
    assert any("selpres/run/config.py" in v for v in spec_room_violations(("run",)))
