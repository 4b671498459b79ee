"""No module of the package imports from a layer above its own (DEVELOPING.md, "Data flow").

Every ``import`` / ``from ... import`` is read with :mod:`ast`, including those inside
functions (a deferred import is still a dependency). Imports of the package root
(``tire_learning_env`` itself: the version, the id registration) are allowed from anywhere.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tire_learning_env"

#: The layers, lowest first: a module may import from its own layer and the layers before it.
#: Keep in step with the "Data flow" section of DEVELOPING.md.
LAYERS = (
    ("_jit_cache",),  # numba's cache keyed on a family of files (stdlib only), for any compiled module
    ("params",),
    ("metrics",),  # scoring functions: pure numpy, used by wrappers and the analysis alike
    ("_kernels",),
    ("tires",),
    ("dynamics",),
    ("roads",),
    ("sensors", "driver", "rendering"),
    ("simulation",),
    ("high_order",),
    ("scenarios",),  # hidden-effect plants, speed profiles and test roads for simulated logs (simulate --effect)
    ("envs", "registration"),
    ("formats", "io"),
    ("observer", "baselines"),
    ("wrappers", "scripted"),
    ("plotting", "studies", "report"),
    ("imu", "discrepancy"),
    ("fleet", "commands", "cli"),
)
RANK = {name: rank for rank, group in enumerate(LAYERS) for name in group}


def _module_name(path: Path) -> str:
    parts = list(path.with_suffix("").relative_to(PACKAGE.parent).parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Absolute names of the package modules ``path`` imports (relative imports resolved)."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = set()
    tree = ast.parse(path.read_text())
    typing_only = {  # imports under ``if TYPE_CHECKING:`` exist for annotations only, never at run time
        id(n) for block in ast.walk(tree)
        if isinstance(block, ast.If) and getattr(block.test, "id", getattr(block.test, "attr", None)) == "TYPE_CHECKING"
        for stmt in block.body for n in ast.walk(stmt)
    }  # fmt: skip
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "tire_learning_env" and node.level:  # "from .. import x": x may be a subpackage
                found.update(f"{target}.{alias.name}" for alias in node.names)
            else:
                found.add(target)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {name for name in found if name.split(".")[0] == "tire_learning_env"}


def _layer_of(module: str) -> str | None:
    """Top-level module or subpackage of ``module`` (``None`` for the package root)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_every_module_has_a_layer():
    tops = {path.stem if path.parent == PACKAGE else path.relative_to(PACKAGE).parts[0] for path in PACKAGE.rglob("*.py")}
    tops.discard("__init__")
    assert not sorted(tops - set(RANK)), "place these modules in LAYERS (tests/test_layering.py) and DEVELOPING.md"


def test_no_module_imports_from_a_layer_above_it():
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = _layer_of(_module_name(path))
        if source is None:  # the package root registers the ids and re-exports
            continue
        for target in sorted(_imports(path)):
            layer = _layer_of(target)
            if layer is None or layer == source or layer not in RANK:
                continue
            if RANK[layer] > RANK[source]:
                upward.append(f"{_module_name(path)} -> {target}")
    assert not upward, "imports from a higher layer:\n" + "\n".join(upward)


def test_the_check_sees_deferred_and_relative_imports(tmp_path):
    """The parser resolves relative imports and finds imports inside functions."""
    path = PACKAGE / "envs" / "lane_keeping.py"
    found = _imports(path)
    assert "tire_learning_env.simulation" in found and "tire_learning_env.envs._base" in found
    assert "tire_learning_env.envs.highway_scenes" in _imports(PACKAGE / "envs" / "highway.py")
    # a deferred import (inside a function) counts: wrappers/excitation.py imports the highway env lazily
    assert "tire_learning_env.envs.highway" in _imports(PACKAGE / "wrappers" / "excitation.py")


def test_simulate_command_does_not_depend_on_the_analysis_package():
    """``tire-learning simulate`` makes logs from :mod:`tire_learning_env.scenarios`; it must not import
    the discrepancy analysis (issue 20), not even lazily."""
    found = _imports(PACKAGE / "commands" / "simulate.py")
    assert "tire_learning_env.scenarios" in found  # the check reads this file's imports at all
    assert not sorted(m for m in found if m.split(".")[:2] == ["tire_learning_env", "discrepancy"]), found


#: Issue 20: no module of the package is longer than this (a longer one holds more than one idea).
MAX_MODULE_LINES = 600


def test_no_module_is_longer_than_600_lines():
    """Every ``.py`` file of the package has at most :data:`MAX_MODULE_LINES` lines."""
    lengths = {p.relative_to(PACKAGE).as_posix(): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    assert len(lengths) > 50  # the walk found the package
    long = {name: n for name, n in lengths.items() if n > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines (split them by idea): {long}"


#: Import cycles (deferred imports included) known on the estimator and analysis side, left to their
#: own issues; any other cycle fails :func:`test_no_import_cycles_between_modules`.
KNOWN_CYCLES = {
    frozenset({"discrepancy.separation", "discrepancy.workflow"}),
}


def _cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycles_between_modules():
    """No two modules import each other, directly or round a loop, deferred imports included (issue 20:
    ``high_order/plant.py`` imported ``simulate`` inside a method while ``simulate`` imported ``plant``).
    A package's ``__init__`` re-exporting its modules is no cycle."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {
        m: {
            t
            for t in _imports(p)
            if t in modules and t != m and not m.startswith(t + ".") and not t.startswith(m + ".")
        }
        for m, p in modules.items()
    }
    cycles = {frozenset(c.removeprefix("tire_learning_env.") for c in cycle) for cycle in _cycles(graph)}
    assert len(graph) > 50  # the walk found the package
    new = sorted(sorted(c) for c in cycles - KNOWN_CYCLES)
    assert not new, f"modules that import each other (break the cycle): {new}"
