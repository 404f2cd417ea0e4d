"""The package's layout draws its architecture (issue 16): dependencies point down only.

Layers, from the bottom: ``control`` (the controller a user drops onto an arm), ``station``
(the simulated world), ``realism`` (the ladder's rungs), ``experiment`` (a scenario to
traces), ``reporting`` (metrics, plots, report), ``studies`` (compare, sweeps); ``cli`` and
the package root on top. A module may import its own layer or a lower one, never a
higher one, and no chain of imports leads from a module back to itself.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "nsdrake"
LAYERS = ("control", "station", "realism", "experiment", "reporting", "driver", "studies")
TOP = len(LAYERS)  # cli, __init__, __main__


def module_name(path: Path) -> str:
    return ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")


def layer(module: str) -> int:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else TOP


def imports(path: Path) -> set[str]:
    """Every nsdrake module ``path`` imports, at module level or inside a function."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("nsdrake"):
            assert node.level == 0, f"{path}: relative import"
            found.add(node.module)
            found |= {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("nsdrake")}
    return found


def graph() -> dict[str, set[str]]:
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {m: {d for d in imports(p) if d in modules and d != m} for m, p in modules.items()}


def test_no_module_imports_a_higher_layer():
    """Catches, e.g., the station reading the scenario type, or the controller taking a
    function from the Fig. 3 trajectory module."""
    up = [f"{m} imports {d}" for m, ds in sorted(graph().items()) for d in sorted(ds) if layer(d) > layer(m)]
    assert not up, "; ".join(up)


def test_no_import_cycle():
    """Catches two modules that import each other, directly or through others (a
    package's __init__ importing its own modules is not a cycle of modules)."""
    edges = {m: {d for d in ds if not m.startswith(d + ".")} for m, ds in graph().items()}
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(m):
        state[m] = 1
        path.append(m)
        for d in sorted(edges[m]):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d) :] + [d]))
            if d not in state:
                visit(d)
        path.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m)


def test_the_layer_check_notices_an_upward_import(tmp_path):
    """The check itself: a control module importing the scenario is caught."""
    bad = tmp_path / "bad.py"
    bad.write_text("from nsdrake.experiment.scenario import Scenario\n")
    assert layer("nsdrake.control.bad") < max(layer(d) for d in imports(bad))


MAX_FUNCTION_LINES = 60  # from `def` to the function's last line, docstring included


def long_functions(path: Path, module: str, limit: int = MAX_FUNCTION_LINES) -> dict[str, int]:
    """{module.qualified_name: lines} of the functions and methods in ``path`` longer than ``limit``."""
    found = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}.{child.name}"
                lines = child.end_lineno - child.lineno + 1
                if not isinstance(child, ast.ClassDef) and lines > limit:
                    found[name] = lines
                visit(child, name)

    visit(ast.parse(path.read_text()), module)
    return found


def test_no_function_is_longer_than_60_lines():
    """STYLE: a function says one thing. Catches a function grown past 60 lines (nested
    functions and methods counted on their own)."""
    long = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        long |= long_functions(p, module_name(p))
    assert not long, "; ".join(f"{name}: {n} lines" for name, n in sorted(long.items()))


def test_the_length_check_counts_a_long_function(tmp_path):
    """The check itself: 61 lines from `def` to the end are caught, 60 are not, methods too."""

    def function(name, lines, indent=""):
        body = "".join(f"{indent}    x{i} = {i}\n" for i in range(lines - 2))
        return f"{indent}def {name}():\n{body}{indent}    return 0\n"

    source = function("f", 61) + function("g", 60) + "class C:\n" + function("h", 61, indent="    ")
    (tmp_path / "m.py").write_text(source)
    assert long_functions(tmp_path / "m.py", "m") == {"m.f": 61, "m.C.h": 61}
