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
