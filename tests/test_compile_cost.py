"""What keeps the first compile of the kernels short (docs/first-run.md).

A slice assignment of an array (``a[:] = b``, ``a[i, :n] = b``) makes numba compile and link a
formatter of the shape-mismatch message into the kernel (``jit/arrays.py``: it doubled the
integration kernels' compile); the kernels copy with ``arrays.copy_into`` and ``copy_rows``.
"""
import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit

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
from numba import njit
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
