"""The README's commands, .ci/run and the docs stay consistent."""

import doctest
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_commands():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```(?:bash|sh)\n(.*?)```", text, flags=re.S)
    return [line.strip() for b in blocks for line in b.splitlines() if line.strip() and not line.startswith("#")]


def test_ci_runs_the_readmes_test_command():
    test_cmds = [c for c in readme_commands() if "pytest" in c and "pip install" in c]
    assert len(test_cmds) == 1, "the README must have exactly one install-and-test command"
    assert test_cmds[0] in (ROOT / ".ci" / "run").read_text()


def test_readme_install_commands_pin_torch_first():
    for cmd in readme_commands():
        if "pip install" in cmd:
            assert cmd.index("pip install torch==2.13.0") < cmd.index("pip install -e")


def test_readme_python_examples_run():
    text = (ROOT / "README.md").read_text()
    parser = doctest.DocTestParser()
    test = parser.get_doctest(text, {}, "README.md", str(ROOT / "README.md"), 0)
    assert test.examples, "the README should contain a runnable example"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert runner.failures == 0


@pytest.mark.parametrize("module", ["tire_learning_env.wrappers.estimator", "tire_learning_env.observer.estimator"])
def test_module_doctests(module):
    import importlib

    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def _extras() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]


def _name(requirement: str) -> str:
    return re.split(r"[<>=!~;\[ ]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def test_ci_installs_the_fleet_extra():
    """CI installs ".[test]" (the README's command): it must carry every package of the fleet extra, so
    the Ray runner, the batch command and the logger formats are tested in CI (issue 19), not skipped."""
    extras = _extras()
    assert '".[test]"' in (ROOT / ".ci" / "run").read_text()
    fleet = {_name(r): r for r in extras["fleet"]}
    test = {_name(r): r for r in extras["test"]}
    assert {"ray", "pyarrow", "asammdf", "mcap", "rosbags", "pyyaml"} <= set(fleet)
    missing = sorted(set(fleet) - set(test))
    assert not missing, f"the test extra lacks the fleet extra's {missing}"
    differ = sorted(n for n in fleet if test[n] != fleet[n])
    assert not differ, f"the test and fleet extras pin {differ} differently"


@pytest.mark.skipif(not os.environ.get("CI"), reason="CI only: there the fleet extra must be installed")
def test_fleet_extra_importable_in_ci():
    """In CI the fleet tests (tests/test_fleet.py, tests/test_formats.py) skip themselves when a package
    is missing; this turns that skip into a failure."""
    import importlib

    for module in ("ray", "pyarrow", "asammdf", "mcap", "rosbags", "yaml"):
        importlib.import_module(module)


# --- DEVELOPING.md's map of where things live (issue 20 item 6) -------------------------------------------

PACKAGE = ROOT / "tire_learning_env"


def _developing_map() -> dict[str, list[str]]:
    """The bullets of DEVELOPING.md's "Where things live": ``{folder or "tests": backticked names}``.

    ``"tire_learning_env/"`` is the package root, ``"baselines/"`` ... a subpackage; the cross-cutting
    bullet is stored under ``"tests"``.
    """
    text = (ROOT / "DEVELOPING.md").read_text()
    start = text.index("## Where things live")
    section = text[start : text.index("\n## ", start + 1)]
    bullets = re.split(r"\n- ", section)[1:]
    found = {}
    for bullet in bullets:
        names = re.findall(r"`([^`]+)`", bullet)
        head = bullet.split(":", 1)[0].strip()
        key = "tests" if head.startswith("Cross-cutting") else head.strip("`")
        assert key not in found, f"DEVELOPING.md map: two bullets for {key}"
        found[key] = names
    return found


def test_developing_map_names_every_module_and_test_file():
    """Every module of the package is listed under its folder, and nothing else; every test file of
    ``tests/`` is named (a top-level module next to its own ``test_<module>.py``), and each named exists."""
    listed = _developing_map()
    folders = {"tire_learning_env/"} | {f"{p.name}/" for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}
    assert set(listed) == folders | {"tests"}, "DEVELOPING.md map: one bullet per folder of the package"
    named_tests = set()
    for folder, names in listed.items():
        modules = {n for n in names if n.endswith(".py") and not n.startswith("test_")}
        named_tests |= {n for n in names if n.startswith("test_") and n.endswith(".py")}
        if folder == "tests":
            continue
        path = PACKAGE if folder == "tire_learning_env/" else PACKAGE / folder
        actual = {p.name for p in path.glob("*.py") if p.name != "__init__.py"}
        assert modules == actual, (
            f"DEVELOPING.md map, {folder}: not listed {sorted(actual - modules)}, no such module {sorted(modules - actual)}"
        )
        assert any(n.startswith("test_") for n in names), f"DEVELOPING.md map, {folder}: name its test files"
    root_names = listed["tire_learning_env/"]
    for module in (n for n in root_names if not n.startswith("test_") and n.endswith(".py")):
        own = f"test_{module.lstrip('_')}"
        assert own in root_names, f"DEVELOPING.md map: {module} without its {own}"
    actual_tests = {p.name for p in (ROOT / "tests").glob("test_*.py")}
    assert named_tests == actual_tests, (
        f"DEVELOPING.md map: test files not named {sorted(actual_tests - named_tests)}, "
        f"no such test file {sorted(named_tests - actual_tests)}"
    )


def test_developing_paths_exist():
    """Every path DEVELOPING.md names (``observer/gains.py``, ``benchmarks/...``) exists, relative to the
    repository or to the package, and so does every file it names bare (``gains.py``)."""
    text = (ROOT / "DEVELOPING.md").read_text()
    paths = {
        tok
        for quoted in re.findall(r"`([^`]+)`", text)
        for tok in re.findall(r"[\w./-]+/[\w./-]+\.(?:py|md|json)\b", quoted)
        if not tok.startswith("../")  # ../shared/: the workspace's shared specification, outside the repository
    }
    assert len(paths) > 20  # the scan found the paths
    missing = sorted(p for p in paths if not (ROOT / p).exists() and not (PACKAGE / p).exists())
    assert not missing, f"DEVELOPING.md names paths that do not exist: {missing}"
    # a bare ``name.py`` is a module of the package, a test file, a benchmark or an example
    bare = {tok for quoted in re.findall(r"`([^`]+)`", text) for tok in re.findall(r"(?<![\w/.])\w+\.py\b", quoted)}
    known = {p.name for folder in (PACKAGE, ROOT / "tests", ROOT / "benchmarks", ROOT / "examples") for p in folder.rglob("*.py")}
    assert not sorted(bare - known), f"DEVELOPING.md names files that do not exist: {sorted(bare - known)}"
