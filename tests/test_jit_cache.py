"""numba's on-disk cache of the compiled estimator (and of the multi-body model) follows edits to any file of its family.

numba keys a cached function on its own file only, so an edit to a compiled callee in another
file would leave the caller's cached machine code in use (:mod:`tire_learning_env._jit_cache`).
The end-to-end test edits a copy of the package: a callee in ``_kernels.py`` (the slip
angles of eq. 13) that the measurement of the correction in ``_kernel_update.py`` calls, and
checks that a fresh process runs the edited callee. Its control runs the same steps with
``key_on_family`` made a no-op and shows the hazard: the process after the edit loads the
stale caller from the cache and prints the first result again (numba 0.68).
"""

import ast
import importlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tire_learning_env._jit_cache import STAMP_TAG, _digest, family_digest, key_on_family
from tire_learning_env.high_order import _mb_kernels
from tire_learning_env.observer import _kernel, _kernel_predict, _kernel_types, _kernel_update

PACKAGE = Path(__file__).resolve().parents[1] / "tire_learning_env"
FAMILY_MODULES = (_kernel_types, _kernel_predict, _kernel_update, _kernel)
# (modules that stamp, the family they stamp with, at least how many compiled functions they define)
FAMILIES = {"observer kernel": (FAMILY_MODULES, _kernel_types.KERNEL_FAMILY, 25),
            "multi-body model": ((_mb_kernels,), _mb_kernels.MB_FAMILY, 11)}  # fmt: skip
# Modules whose compiled functions call compiled functions of another file but do not key their
# cache on a family yet (DEVELOPING.md lists them): an edit to their callees needs a cache clear.
NOT_YET_KEYED: dict = {}

# The IMU measurement of the correction (``_kernel_update``), which calls the forces (``_kernel_predict``)
# and the slip angles (``tire_learning_env._kernels``), on an observer's own arguments: a cheap cross-file compile.
PROBE = """
import json
from types import SimpleNamespace

import numpy as np
from tire_learning_env.observer import _kernel as K
from tire_learning_env.observer._kernel_update import _measurement
from tire_learning_env.observer.basis import imu_basis
from tire_learning_env.observer.certificate import ObserverGains
from tire_learning_env.observer.model import measurement_model
from tire_learning_env.params import VehicleParams
from tire_learning_env.observer.neuro_adaptive import NeuroAdaptiveObserver

vehicle = VehicleParams()
gains = ObserverGains(measurement_model("imu"), np.array([0.0, 100.0]), np.zeros((1, 2, 2)), np.zeros((1, 2, 2)),
                      np.zeros((2, 2)), [SimpleNamespace(decay_rate=1.0, period=0.01, certified=True)])
obs = NeuroAdaptiveObserver(vehicle, imu_basis(vehicle), gains, [0.01, 0.01, 0.1, 0.01]).reset()
wk = K.make_work(2, obs.n_weights, obs._bounds[0].shape[1])
z = np.array([np.nan, np.nan, 2.0, 0.05])
nu = _measurement(K.GROUP_IMU, obs._state, 0.02, 20.0, obs._model_tuple, obs._settings(K.MODE_CAUSAL, 0.0), z, wk)
print(json.dumps([float(nu[0]), float(nu[1])]))
"""


# The multi-body model's right-hand side (``_mb_kernels``), which calls the PAC2002 tire (``_pac2002``).
PROBE_MB = """
import json

import numpy as np
from tire_learning_env.high_order import _mb_kernels as K
from tire_learning_env.high_order.params import HighOrderConfig, MultiBodyParams
from tire_learning_env.high_order.plant import parameter_vector, static_state, tire_vector

params = MultiBodyParams.from_commonroad(2)
x = static_state(params, 20.0)
x[K.S_VY], x[K.S_R] = 0.3, 0.1
f, aux = np.zeros(K.N_STATE), np.zeros(K.N_AUX)
K.mb_rhs(x, 0.0, 0.0, parameter_vector(params, HighOrderConfig()), tire_vector(params.tire), False, f, aux)
print(json.dumps([float(f[K.S_VY]), float(aux[K.AUX_FY + K.W_LF])]))
"""


def _probe(root: Path, probe: str = PROBE) -> list[float]:
    env = dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)  # the copy's own __pycache__ (numba's default in a writable tree)
    env.pop("NUMBA_DISABLE_JIT", None)
    done = subprocess.run([sys.executable, "-c", probe], env=env, cwd=root, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} not found once in {path.name}"
    path.write_text(text.replace(old, new))


SLIP = "return delta - (vy + lf * r) / vx, (lr * r - vy) / vx"
SLIP_EDITED = "return 2.0 * (delta - (vy + lf * r) / vx), (lr * r - vy) / vx"  # the front slip doubled


@pytest.mark.slow
@pytest.mark.parametrize("guard", [True, False], ids=["family stamp", "numba alone (the hazard)"])
def test_an_edited_callee_in_another_file_is_recompiled(tmp_path, guard):
    root = tmp_path / "copy"
    shutil.copytree(PACKAGE, root / "tire_learning_env", ignore=shutil.ignore_patterns("__pycache__"))
    if not guard:  # the control: numba's own stamp only
        _edit(root / "tire_learning_env" / "_jit_cache.py", "    digest = family_digest(files)\n",
              "    return 0\n    digest = family_digest(files)\n")
    callee = root / "tire_learning_env" / "_kernels.py"  # eq. (13), one file up from the observer's kernels
    first = _probe(root)
    assert list((root / "tire_learning_env" / "observer" / "__pycache__").glob("_kernel_update._measurement-*.nbi")), \
        "the measurement was not cached: the test would not exercise the cache"
    assert _probe(root) == first  # same source: loaded from the cache, same result
    _edit(callee, SLIP, SLIP_EDITED)
    edited = _probe(root)
    if not guard:
        assert edited == first, "numba now follows edits across files by itself: the family stamp may be dropped"
        return
    assert edited != first, "the edited callee did not reach the cached caller (stale machine code ran)"
    _edit(callee, SLIP_EDITED, SLIP)  # the edit is what ran: undoing it gives the first result back
    assert _probe(root) == first


PAC_LATERAL = "F_y = D_y * math.sin(_mf_angle(alpha_y, B_y, C_y, E_y)) + S_vy"
PAC_LATERAL_EDITED = "F_y = 2.0 * D_y * math.sin(_mf_angle(alpha_y, B_y, C_y, E_y)) + S_vy"  # peak doubled


@pytest.mark.slow
@pytest.mark.parametrize("guard", [True, False], ids=["family stamp", "numba alone (the hazard)"])
def test_an_edited_tire_function_reaches_the_cached_multi_body_model(tmp_path, guard):
    """The same for the multi-body family: an edit to ``_pac2002.pac_lateral`` reaches ``_mb_kernels.mb_rhs``."""
    root = tmp_path / "copy"
    shutil.copytree(PACKAGE, root / "tire_learning_env", ignore=shutil.ignore_patterns("__pycache__"))
    if not guard:
        _edit(root / "tire_learning_env" / "_jit_cache.py", "    digest = family_digest(files)\n",
              "    return 0\n    digest = family_digest(files)\n")
    callee = root / "tire_learning_env" / "high_order" / "_pac2002.py"
    first = _probe(root, PROBE_MB)
    assert list((root / "tire_learning_env" / "high_order" / "__pycache__").glob("_mb_kernels.mb_rhs-*.nbi")), \
        "mb_rhs was not cached: the test would not exercise the cache"
    assert _probe(root, PROBE_MB) == first
    _edit(callee, PAC_LATERAL, PAC_LATERAL_EDITED)
    edited = _probe(root, PROBE_MB)
    if not guard:
        assert edited == first, "numba now follows edits across files by itself: the family stamp may be dropped"
        return
    assert edited != first, "the edited tire function did not reach the cached model (stale machine code ran)"
    _edit(callee, PAC_LATERAL_EDITED, PAC_LATERAL)
    assert _probe(root, PROBE_MB) == first


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_every_compiled_function_of_the_family_is_stamped_with_its_digest(family):
    modules, files, at_least = FAMILIES[family]
    digest = family_digest(files)
    assert digest is not None and len(digest) == 64
    stamped = 0
    for module in modules:
        for obj in vars(module).values():
            if getattr(obj, "py_func", None) is not None and obj.py_func.__module__ == module.__name__:
                stamp = obj._cache._cache_file._source_stamp
                assert stamp[:2] == (STAMP_TAG, digest), f"{module.__name__}.{obj.py_func.__name__} is not stamped"
                stamped += 1
    assert stamped >= at_least  # the family's compiled functions (numba internals changed if none is found)


def _compiled_files(obj) -> set[Path]:
    """Source files defining the compiled function ``obj``, or every compiled function a module ``obj`` holds."""
    objs = vars(obj).values() if isinstance(obj, type(sys)) else [obj]
    return {Path(sys.modules[o.py_func.__module__].__file__).resolve()
            for o in objs if getattr(o, "py_func", None) is not None}  # fmt: skip


def _cross_file_callees(path: Path) -> tuple[str, set[Path]]:
    """A package module's name and the other files whose compiled functions its imports bring in."""
    name = ".".join(("tire_learning_env",) + path.relative_to(PACKAGE).with_suffix("").parts)
    callees = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = importlib.import_module(
                importlib.util.resolve_name("." * node.level + (node.module or ""), name.rsplit(".", 1)[0]))
            for alias in node.names:
                obj = getattr(base, alias.name, None)
                if obj is None:  # a submodule not yet imported
                    obj = importlib.import_module(f"{base.__name__}.{alias.name}")
                callees |= _compiled_files(obj)
    callees.discard(path.resolve())
    return name, callees


def test_every_module_calling_compiled_code_of_another_file_keys_its_cache_on_a_family_holding_it():
    """Scans the whole package: a module that defines compiled functions and imports compiled
    functions from another file ends with ``key_on_family(globals(), FAMILY)`` and its FAMILY
    lists that file (or it is one of the known ``NOT_YET_KEYED``)."""
    checked = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        if not any(isinstance(node, ast.Name) and node.id == "njit" for node in ast.walk(tree)):
            continue
        name, callees = _cross_file_callees(path)
        keys = [node for node in ast.walk(tree) if isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name) and node.func.id == "key_on_family"]  # fmt: skip
        if name in NOT_YET_KEYED:
            assert callees, f"{name} calls no compiled function of another file: drop it from NOT_YET_KEYED"
            assert not keys, f"{name} is keyed now: drop it from NOT_YET_KEYED"
            checked.add(name)
            continue
        if not callees:
            continue
        assert keys, f"{name} calls compiled code of {sorted(c.name for c in callees)} without key_on_family"
        family_arg = keys[0].args[1]
        assert isinstance(family_arg, ast.Name), f"{name}: name the family in a module constant"
        family = {Path(f).resolve() for f in getattr(importlib.import_module(name), family_arg.id)}
        assert path.resolve() in family, f"{name}'s family {family_arg.id} misses its own file"
        assert callees <= family, f"{name}'s family {family_arg.id} misses {sorted(c.name for c in callees - family)}"
        checked.add(name)
    assert {"tire_learning_env.high_order._mb_kernels", "tire_learning_env.observer._kernel",
            "tire_learning_env.discrepancy._model", "tire_learning_env.discrepancy._body_model",
            "tire_learning_env.baselines.kalman"} <= checked
    assert set(NOT_YET_KEYED) <= checked


def test_the_family_lists_every_observer_module_that_holds_compiled_functions():
    """A module that defines compiled functions and imports from the family belongs to it
    (else its cache would not follow the family's edits)."""
    family = {path.resolve().relative_to(PACKAGE.resolve()).as_posix() for path in _kernel_types.KERNEL_FAMILY}
    assert all((PACKAGE / name).exists() for name in family) and "_kernels.py" in family  # eq. 13 lives there
    for path in sorted((PACKAGE / "observer").glob("*.py")):
        tree = ast.parse(path.read_text())
        jitted = any(isinstance(node, ast.Name) and node.id == "njit" for node in ast.walk(tree))
        uses_family = any(isinstance(node, ast.ImportFrom) and (node.module or "").startswith("_kernel")
                          for node in ast.walk(tree))  # fmt: skip
        if jitted and uses_family:
            assert f"observer/{path.name}" in family, f"{path.name} calls the compiled family: add it to KERNEL_FAMILY"


def test_the_digest_follows_every_file_and_a_restamp_keeps_numbas_own_stamp(tmp_path):
    files = [tmp_path / "a.py", tmp_path / "b.py"]
    for f, text in zip(files, ("x = 1\n", "y = 2\n")):
        f.write_text(text)
    before = family_digest(files)
    files[1].write_text("y = 3\n")
    _digest.cache_clear()  # the digest is computed once per process and list of paths
    assert family_digest(files) != before
    assert family_digest([tmp_path / "missing.py"]) is None
    assert key_on_family({"__name__": "m"}, [tmp_path / "missing.py"]) == 0

    class _File:
        _source_stamp = (1.0, 10)

    class _Cache:
        _cache_file = _File()

    def f():
        pass

    f.__module__ = "m"

    class _Dispatcher:
        py_func = f
        _cache = _Cache()

    namespace = {"__name__": "m", "f": _Dispatcher()}
    assert key_on_family(namespace, files) == 1
    assert key_on_family(namespace, files) == 1  # idempotent: numba's stamp kept, not nested
    assert namespace["f"]._cache._cache_file._source_stamp == (STAMP_TAG, family_digest(files), (1.0, 10))
