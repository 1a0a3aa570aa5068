"""Who calls the one compiled covariance update, and numba's cache of the kernels that call another module's.

Every compiled function of the package that updates a covariance calls
:func:`kalcal.core.kernels.covariance_update`; the fixed-gain block kernel applies its precomputed gains
and has no covariance update. numba keys a cached kernel on its own source file only, so a kernel that
compiled another module's function into itself is stale once that module changes: each such module
carries a stamp of its callees' sources (the second test), so that a callee's change changes the caller's
file too.
And no compiled function outside kalcal.core.kernels writes a covariance or information update of its
own (the last tests: a scan of each one's syntax tree for the shapes of such an update, what it covers
stated in :func:`covariance_update_patterns`).
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import inspect
import pkgutil
import sys
import textwrap

import kalcal
from numba.core.dispatcher import Dispatcher

from kalcal.core import kernels


def _compiled_modules():
    """Every kalcal module that compiles a function, imported."""
    for info in pkgutil.walk_packages(kalcal.__path__, "kalcal."):
        spec = importlib.util.find_spec(info.name)
        if spec.origin and spec.origin.endswith(".py") and "numba.njit" in open(spec.origin, encoding="utf-8").read():
            importlib.import_module(info.name)
    return {name: module for name, module in sys.modules.items() if name.startswith("kalcal.")}


def _kernels(modules):
    """(module name, function name) -> dispatcher, for the functions each module defines."""
    return {
        (name, key): value
        for name, module in modules.items()
        for key, value in vars(module).items()
        if isinstance(value, Dispatcher) and value.py_func.__module__ == name
    }


def _callees(dispatcher):
    """The compiled functions a kernel names (its globals that are dispatchers)."""
    names = dispatcher.py_func.__code__.co_names
    scope = dispatcher.py_func.__globals__
    return [scope[n] for n in names if isinstance(scope.get(n), Dispatcher)]


def test_every_compiled_covariance_update_is_the_one_function():
    found = _kernels(_compiled_modules())
    callers = {key for key, kernel in found.items() if kernels.covariance_update in _callees(kernel)}
    assert callers == {
        ("kalcal.filters.sequential", "_run"),
        ("kalcal.scenarios.scale_bias.kernels", "_filter_tile"),
        ("kalcal.scenarios.scale_bias.likelihood", "_diffuse_filter"),
        ("kalcal.core.timevarying_kernels", "run_rows"),
        ("kalcal.scenarios.nonlinear.kernel", "ekf_block"),
    }
    # the information filter's diffuse start, compiled once (core.kernels.diffuse_start), run by the likelihood
    starters = {key for key, kernel in found.items() if kernels.diffuse_start in _callees(kernel)}
    assert starters == {("kalcal.scenarios.scale_bias.likelihood", "_diffuse_filter")}
    # the fixed-gain block kernel applies its gain schedule: its module was walked (so the set above,
    # which leaves it out, says that no covariance update is in it)
    assert any(name == "kalcal.montecarlo.kernels" for name, _ in found)


def _stamp_line(callees: set[str]) -> str:
    """The line a module whose kernels compile ``callees`` (module names) into themselves must carry: each
    callee with the first 16 hex digits of the SHA-256 of its source as it is now."""
    parts = []
    for name in sorted(callees):
        digest = hashlib.sha256(open(sys.modules[name].__file__, "rb").read()).hexdigest()[:16]
        parts.append(f"{name} {digest}")
    return "# numba cache stamp: " + ", ".join(parts)


def test_every_kernel_that_compiles_another_modules_function_carries_its_stamp():
    """numba keys a cached kernel on its own source file alone, so a kernel that compiled a function of
    another module into itself would be loaded stale after that module changed (in a checkout, and after an
    upgrade, which leaves numba's cache files in place). Each such module carries a line naming each callee
    module with the digest of its source: a change to a callee fails this test until the caller's line is
    renewed, and the renewed line changes the caller's file, which numba's own cache then sees. The line of
    a callee is part of its source, so a change two modules down renews every module up the chain."""
    found = _kernels(_compiled_modules())
    callees: dict[str, set[str]] = {}
    for (name, _), kernel in found.items():
        for callee in _callees(kernel):
            module = callee.py_func.__module__
            if module != name:
                callees.setdefault(name, set()).add(module)
    assert callees, "no kernel calls another module's: the test found nothing to hold"
    wrong = []
    for name, modules in sorted(callees.items()):
        expected = _stamp_line(modules)
        lines = [line.rstrip("\n") for line in open(sys.modules[name].__file__, encoding="utf-8")]
        if expected not in lines:
            wrong.append(f"{sys.modules[name].__file__}: needs the line\n{expected}")
    assert not wrong, "stale numba cache stamps (each caller would load its cached kernels compiled against the old callee):\n" + "\n".join(wrong)
    # and no module carries a stamp for callees it no longer compiles in
    for name, module in _compiled_modules().items():
        if module.__file__ and name not in callees:
            lines = open(module.__file__, encoding="utf-8").read().splitlines()
            assert not any(line.startswith("# numba cache stamp:") for line in lines), name


# --- hand-written covariance updates in compiled functions ------------------------------------------------


def _is_kronecker_delta(node, deltas):
    """``1.0 if u == v else 0.0``, or a name bound to one."""
    if isinstance(node, ast.Name):
        return node.id in deltas
    return (
        isinstance(node, ast.IfExp) and isinstance(node.test, ast.Compare) and isinstance(node.test.ops[0], ast.Eq)
        and isinstance(node.body, ast.Constant) and node.body.value == 1 and isinstance(node.orelse, ast.Constant)
        and node.orelse.value == 0
    )  # fmt: skip


def _indices(node) -> int:
    """How many indices a subscript takes (0 for anything else)."""
    if not isinstance(node, ast.Subscript):
        return 0
    return len(node.slice.elts) if isinstance(node.slice, ast.Tuple) else 1


def _products(node):
    """The Mult nodes within an expression."""
    return [n for n in ast.walk(node) if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Mult)]


def _base(node):
    while isinstance(node, ast.Subscript):
        node = node.value
    return ast.unparse(node)


def covariance_update_patterns(source: str) -> list[str]:
    """The shapes of a hand-written covariance (or information) update in a function's source.

    Four patterns of the syntax tree (comments and docstrings play no part), each what a covariance update
    written out in loops cannot avoid and what the package's other compiled arithmetic does not do:

    - ``P[u, v] -= K[..] * (H M)[..]``: a matrix entry (two or more indices) decreased by a product, the
      standard form's P = M - K H M;
    - ``delta - K[..] * H[..]`` with ``delta`` a Kronecker delta (``1.0 if u == v else 0.0``, or a name
      bound to one): the Joseph form's I - K H;
    - ``Y[i, j] += h[.., i] * h[.., j] / r``: an outer product of one vector with itself, divided,
      accumulated into a matrix entry: the information update (into a scalar, ``y11 += z * z / r``, it
      is not told from a sum of squares, a NIS's or a Ljung-Box statistic's: the next pattern catches
      a 2 x 2 form written out in scalars by its inverse);
    - ``a * d - b * c`` bound to a name that a later expression divides by: a 2 x 2 determinant and the
      inverse by cofactors, the information form's (I + Q Y)^{-1} or P = Y^{-1} written out.

    It does not see an update through calls to another function than the scanned one (a helper in the
    same module is scanned on its own, being compiled too), nor one in vectorized numpy expressions
    (``P - K @ H @ P``) inside a compiled function, nor one spelled otherwise (a Cholesky downdate).
    """
    tree = ast.parse(textwrap.dedent(source))
    deltas = {
        target.id
        for node in ast.walk(tree) if isinstance(node, ast.Assign) and _is_kronecker_delta(node.value, set())
        for target in node.targets if isinstance(target, ast.Name)
    }  # fmt: skip
    dets = {}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Sub) and _indices(node.target) >= 2:
            if any(_indices(f.left) and _indices(f.right) for f in _products(node.value)):
                found.append(f"{node.lineno}: a matrix entry less a product (P = M - K H M)")
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub) and _is_kronecker_delta(node.left, deltas):
            if _products(node.right):
                found.append(f"{node.lineno}: a Kronecker delta less a product (I - K H)")
        if isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Add) and isinstance(node.value, ast.BinOp):
            value = node.value
            if isinstance(value.op, ast.Div) and isinstance(value.left, ast.BinOp) and isinstance(value.left.op, ast.Mult):
                left, right = value.left.left, value.left.right
                same = _base(left) == _base(right) and (
                    ast.unparse(left) == ast.unparse(right) or (_indices(left) and _indices(right))
                )
                if same and _indices(node.target) >= 2:
                    found.append(f"{node.lineno}: an outer product of one vector accumulated (Y += h h^T / R)")
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.BinOp) and isinstance(node.value.op, ast.Sub):
            parts = (node.value.left, node.value.right)
            if all(isinstance(p, ast.BinOp) and isinstance(p.op, ast.Mult) for p in parts):
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        dets[target.id] = node.lineno
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) and isinstance(node.right, ast.Name):
            if node.right.id in dets:
                found.append(f"{dets[node.right.id]}: a 2 x 2 determinant divided by (an inverse by cofactors)")
                dets.pop(node.right.id)
    return found


def test_no_compiled_function_outside_core_kernels_writes_a_covariance_update():
    """Every compiled function of the package outside kalcal.core.kernels, scanned for the patterns of
    :func:`covariance_update_patterns` (whose docstring says what they cover and what not)."""
    found = _kernels(_compiled_modules())
    assert len(found) > 10  # the walk saw the package's kernels
    hits = [
        f"{name}.{function}: {hit}"
        for (name, function), kernel in sorted(found.items())
        if name != "kalcal.core.kernels"
        for hit in covariance_update_patterns(inspect.getsource(kernel.py_func))
    ]
    assert not hits, "covariance updates written outside kalcal.core.kernels:\n" + "\n".join(hits)


def test_the_scan_sees_each_pattern_and_core_kernels_own():
    """A test of the scan: the updates core.kernels writes are caught in it, and the diffuse likelihood as it
    was (its information-form start written out in 2 x 2 closed form) is caught."""
    for function in (kernels._scalar_update, kernels._general_update, kernels.diffuse_start):
        assert covariance_update_patterns(inspect.getsource(function.py_func)), function
    hits = covariance_update_patterns(OLD_DIFFUSE_FILTER)
    assert any("determinant" in h for h in hits), hits
    assert covariance_update_patterns("def f(p, k, hp):\n    for u in range(2):\n        for v in range(2):\n            p[u, v] -= k[u] * hp[v]\n")
    assert covariance_update_patterns("def f(a, k, h):\n    a[0, 1] = (1.0 if 0 == 1 else 0.0) - k[0] * h[1]\n")
    assert not covariance_update_patterns("def f(x, k, r):\n    x[0] += k[0] * r\n    s = r * r / 2.0\n")


#: the compiled diffuse likelihood's start before it called core.kernels.diffuse_start (abridged)
OLD_DIFFUSE_FILTER = '''
def _diffuse_filter(reference, sensor, r, q2, normalized):
    y11 = y12 = y22 = 0.0
    i1 = i2 = 0.0
    for k in range(reference.size):
        v, z = reference[k], sensor[k]
        if q2 > 0.0:
            a11, a12, a21, a22 = 1.0 + q2 * y11, q2 * y12, q2 * y12, 1.0 + q2 * y22
            det = a11 * a22 - a12 * a21
            m11, m12, m21, m22 = a22 / det, -a12 / det, -a21 / det, a11 / det
            y11, y12, y22 = m11 * y11 + m12 * y12, m11 * y12 + m12 * y22, m21 * y12 + m22 * y22
        y11 += z * z / r
        y12 += z / r
        y22 += 1.0 / r
        det = y11 * y22 - y12 * y12
'''
