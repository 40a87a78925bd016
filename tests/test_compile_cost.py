"""What keeps the first compile of the kernels short (docs/first-run.md).

A slice assignment of an array (``a[:] = b``, ``a[i, :n] = b``) makes numba compile and link a
formatter of the shape-mismatch message into the kernel (``jit/arrays.py``: it doubled the
integration kernels' compile); the kernels copy with ``arrays.copy_into`` and ``copy_rows``.
"""
import ast
import gc
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from numba.core.runtime import _nrt_python, rtsys

from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.arrays import copy_into, copy_rows

RUNTIME = Path(cache_guard.__file__).parents[1]


def _constant(node) -> bool:
    """A value that is a scalar constant for sure: 0.0, -1, False, np.nan, math.inf."""
    if isinstance(node, ast.UnaryOp):
        return _constant(node.operand)
    return isinstance(node, ast.Constant) or (isinstance(node, ast.Attribute) and node.attr in ("nan", "inf"))


def _sliced(target) -> bool:
    index = target.slice
    return isinstance(index, ast.Slice) or (isinstance(index, ast.Tuple)
                                            and any(isinstance(e, ast.Slice) for e in index.elts))


def slice_assignments(source: Path) -> list[str]:
    """The statements of ``source`` that assign anything but a constant to a slice."""
    found = []
    for node in ast.walk(ast.parse(source.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Assign):
            continue
        for target in node.targets:
            pairs = (zip(target.elts, node.value.elts) if isinstance(target, ast.Tuple)
                     and isinstance(node.value, ast.Tuple) else [(target, node.value)])
            if any(isinstance(t, ast.Subscript) and _sliced(t) and not _constant(v) for t, v in pairs):
                found.append(f"{source.name}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_the_kernels_assign_no_array_to_a_slice():
    found = [hit for name in cache_guard.KERNEL_SOURCES for hit in slice_assignments(RUNTIME / name)]
    assert not found, "use arrays.copy_into / copy_rows instead:\n" + "\n".join(found)


def test_the_check_sees_slice_assignments(tmp_path):
    source = tmp_path / "kernel.py"
    source.write_text("def f(a, b, z, s):\n    a[:] = b\n    a[0, :2] = b\n    z[0], z[1:] = s, b\n"
                      "    a[:] = 0.0\n    a[:, :] = np.nan\n    a[0] = b\n")
    assert [hit.split(":")[1] for hit in slice_assignments(source)] == ["2", "3", "4"]


@njit
def _copies(a, b, m, n):
    copy_into(a[1:3], b[2:])
    copy_rows(m[1:], n[:2, ::-1])


def test_copy_into_and_copy_rows_copy_views_element_by_element():
    a, b = np.zeros(4), np.arange(4.0)
    m, n = np.zeros((3, 3)), np.arange(9.0).reshape(3, 3)
    expected = m.copy()
    expected[1:] = n[:2, ::-1]
    _copies(a, b, m, n)
    assert a.tolist() == [0.0, 2.0, 3.0, 0.0]
    assert m.tolist() == expected.tolist()


_PROBE = '''
import numpy as np
import pytest
from numba import njit
from numba.core.runtime import _nrt_python, rtsys
from numba.core import event
from tswm_runtime.jit.arrays import copy_into
compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(getattr(ev.data["dispatcher"], "py_func", None).__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
@njit
def by_loop(a, b):
    copy_into(a, b)
by_loop(np.zeros(3), np.ones(3))
print(sum("shape_context" in name for name in compiled))
@njit
def by_slice(a, b):
    a[:] = b
by_slice(np.zeros(3), np.ones(3))
print(sum("shape_context" in name for name in compiled))
'''


@pytest.mark.heavy
def test_numba_compiles_a_shape_message_for_a_slice_assignment_and_none_for_copy_into(tmp_path):
    """The premise of jit/arrays.py, checked on the installed numba (in a fresh process: numba
    compiles the message once per process)."""
    done = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, cwd=tmp_path,
                          env={"PYTHONPATH": str(RUNTIME.parent), "PATH": "", "NUMBA_CACHE_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["0", "1"]


# The kernels' helpers are compiled without numba's reference counting unless they make arrays
# (``cache_guard.njit(refcounted=True)``): counting was over a third of the code numba typed, lowered
# and LLVM optimized. What makes that safe is checked when a helper compiles, and by the count of
# numba's allocations after real runs.

@cache_guard.njit(error_model="numpy")
def _uncounted_identity(a):
    return a


@cache_guard.njit(error_model="numpy", refcounted=True)
def _counted_identity(a):
    return a


@njit
def _fresh(n):
    """A new array; compiled with reference counting when called from Python first (a numba.njit
    function called first from a helper without it inherits that, and then cannot allocate)."""
    return np.zeros(n)


@cache_guard.njit(error_model="numpy")
def _uncounted_sum_of_fresh(n):
    return _fresh(n).sum()


@njit
def _through(helper, a):
    return helper(a)


def test_a_helper_without_reference_counting_returns_no_array():
    a = np.arange(3.0)
    with pytest.raises(Exception, match="_uncounted_identity returns array.*refcounted=True"):
        _through(_uncounted_identity, a)
    assert _through(_counted_identity, a).tolist() == [0.0, 1.0, 2.0]


def test_a_helper_without_reference_counting_takes_no_array_from_compiled_code():
    _fresh(3)
    with pytest.raises(Exception, match=r"_uncounted_sum_of_fresh takes array\(float64, 1d, C\) from .*refcounted=True"):
        _through(_uncounted_sum_of_fresh, 3)


def _unreleased(run) -> tuple[int, int]:
    """(allocations, meminfos) that ``run()`` left unreleased in numba's runtime, its results freed."""
    _nrt_python.memsys_enable_stats()   # numba counts from here on (NUMBA_NRT_STATS does it at start)
    gc.collect()
    before = rtsys.get_allocation_stats()
    run()
    gc.collect()
    after = rtsys.get_allocation_stats()
    return (after.alloc - after.free) - (before.alloc - before.free), \
        (after.mi_alloc - after.mi_free) - (before.mi_alloc - before.mi_free)


def test_the_count_sees_an_array_left_unreleased(monkeypatch):
    """The instrument of the test below: an uncounted helper that drops an array it was given
    (the check switched off) leaves one allocation behind per call."""
    monkeypatch.setattr(cache_guard, "_check_uncounted", lambda *args: None)

    @cache_guard.njit(error_model="numpy")
    def leaky(n):
        return _fresh(n).sum()

    _fresh(2)
    _through(leaky, 2)
    assert _unreleased(lambda: [_through(leaky, 2) for _ in range(3)]) == (3, 3)


@pytest.mark.parametrize("scene", ["paper", "backlash", "lost-motion", "stiff-drive"])
def test_runs_leave_no_array_of_numba_unreleased(scene):
    """Every method's run of a scene with impacts, a pickup or a stiff drive, a sweep's batch and
    a chain's run free every array numba made (after a first run: memos keep theirs)."""
    from tswm_runtime.simulation.simulate import simulate

    def runs():
        for method in ("dopri5", "rosenbrock23", "rodas4", "auto"):
            result = simulate(scene, method=method, points=50)
            result.S1, result.sol(result.t[-1])
    runs()
    assert _unreleased(runs) == (0, 0)
