"""The package's layers: numerics never import the edge; modules stay small.

Read from the source with :mod:`ast` (every import, including those inside functions), so
that a lazy import cannot hide an upward arrow.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "bayesplate"
#: The edge: case files, importers, export, figures, report, command line.
EDGE = ("io", "case", "importers", "plots", "run", "report", "batch", "cli")
#: Pure computation: everything below the edge.
NUMERICS = (
    "quantities",
    "laminate",
    "parallel",
    "settings",
    "fem",
    "plate",
    "matching",
    "likelihood",
    "estimators",
    "reduced",
    "sampling",
    "discrepancy",
)
#: The numerics' root modules, which everything uses: they import no group below.
ROOT = ("quantities", "laminate", "parallel", "settings")
#: The root's groups by idea, in order: each imports only the root, ``fem`` and the groups
#: before it (the plate model; matching measured peaks with its modes; the likelihood).
GROUPS = ("plate", "matching", "likelihood")
MAX_LINES = 500
#: A module longer than MAX_LINES must say why in its docstring with this phrase.
REASON = "Longer than 500 lines because"


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "data" not in p.relative_to(PACKAGE).parts)


def _top(path):
    """The top-level room of a module: ``bayesplate/sampling/chain.py`` -> "sampling"."""
    return path.relative_to(PACKAGE).parts[0].removesuffix(".py")


def _imports(path, package=PACKAGE):
    """Each name `path` imports anywhere in it (absolute or relative, lazy too), resolved.

    One tuple a name, most specific first: ``from .chain import sample`` in
    ``bayesplate/sampling/x.py`` gives ``("bayesplate.sampling.chain.sample",
    "bayesplate.sampling.chain")`` (the name may be a submodule or a name in that module).
    """
    package_parts = ("bayesplate",) + path.relative_to(package).parent.parts
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(a.name,) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                module = (node.module,) if node.module else ()
                base = ".".join(package_parts[: len(package_parts) - node.level + 1] + module)
            found += [(f"{base}.{a.name}", base) for a in node.names]
    return found


def _imported_rooms(path, package=PACKAGE):
    """Top-level rooms of bayesplate that `path` imports (absolute or relative)."""
    parts = (names[0].split(".") for names in _imports(path, package))
    return {p[1] for p in parts if p[0] == "bayesplate" and len(p) > 1}


def test_every_module_is_in_a_layer():
    rooms = {_top(p) for p in _modules()} - {"__init__", "_version"}
    assert rooms <= set(EDGE) | set(NUMERICS), rooms - set(EDGE) - set(NUMERICS)


@pytest.mark.parametrize(
    "path",
    [p for p in _modules() if _top(p) in NUMERICS],
    ids=lambda p: str(p.relative_to(PACKAGE)),
)
def test_numerics_import_nothing_from_the_edge(path):
    upward = _imported_rooms(path) & set(EDGE)
    assert not upward, f"{path.relative_to(PACKAGE)} imports the edge: {sorted(upward)}"


@pytest.mark.parametrize(
    "path",
    [p for p in _modules() if _top(p) in ROOT + GROUPS],
    ids=lambda p: str(p.relative_to(PACKAGE)),
)
def test_the_root_and_its_groups_import_only_downward(path):
    top = _top(path)
    below = {"fem", *ROOT, *GROUPS[: GROUPS.index(top) + 1]} if top in GROUPS else set(ROOT)
    upward = _imported_rooms(path) - below
    assert not upward, f"{path.relative_to(PACKAGE)} imports above it: {sorted(upward)}"


def test_the_layer_check_sees_lazy_and_relative_imports(tmp_path):
    # the check itself: relative imports inside a function, and absolute ones, are seen
    fake = tmp_path / "bayesplate" / "sampling" / "probe.py"
    fake.parent.mkdir(parents=True)
    fake.write_text(
        "import bayesplate.cli\n"
        "def f():\n    from ..io import write_json\n    from .. import report\n"
        "    from .chain import sample\n"
    )
    assert _imported_rooms(fake, tmp_path / "bayesplate") == {"cli", "io", "report", "sampling"}


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_modules_are_small_or_say_why(path):
    text = path.read_text()
    lines = text.count("\n")
    if lines <= MAX_LINES:
        return
    doc = ast.get_docstring(ast.parse(text)) or ""
    assert REASON in doc, f"{lines} lines and no '{REASON} ...' in the docstring"


def _dotted(path, package=PACKAGE):
    """``bayesplate/io/taps.py`` -> ``"bayesplate.io.taps"``; a package's ``__init__`` its name."""
    parts = ("bayesplate",) + path.relative_to(package).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported_modules(path, known, package=PACKAGE):
    """Modules of `known` that `path` imports anywhere in it (a name of a package's
    ``from . import name`` counts as its submodule when there is one)."""
    found = {next((n for n in names if n in known), None) for names in _imports(path, package)}
    return found - {None, _dotted(path, package)}


def _circles(package=PACKAGE):
    """Sets of modules that import one another in a circle (strongly connected, size > 1)."""
    known = {_dotted(p, package): p for p in package.rglob("*.py")}
    graph = {m: _imported_modules(p, known, package) for m, p in known.items()}

    def reaches(start):
        seen, todo = set(), [start]
        while todo:
            for nxt in graph[todo.pop()] - seen:
                seen.add(nxt)
                todo.append(nxt)
        return seen

    reach = {m: reaches(m) for m in graph}
    circles = {frozenset({m} | {n for n in reach[m] if m in reach[n]}) for m in graph}
    return sorted(sorted(c) for c in circles if len(c) > 1)


def test_no_import_circle():
    """No module imports, through any chain and any lazy import, a module that imports it."""
    assert _circles() == []


def test_the_circle_check_sees_a_lazy_circle(tmp_path):
    package = tmp_path / "bayesplate"
    (package / "io").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "io" / "__init__.py").write_text("from .a import f\n")
    (package / "io" / "a.py").write_text("def f():\n    from .b import g\n")
    (package / "io" / "b.py").write_text("from ..io import f\n")
    (package / "model.py").write_text("from . import laminate\n")
    (package / "laminate.py").write_text("")
    assert _circles(package) == [["bayesplate.io", "bayesplate.io.a", "bayesplate.io.b"]]
