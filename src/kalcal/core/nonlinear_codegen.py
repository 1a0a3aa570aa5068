"""A nonlinear model's f, h and their Jacobians printed as scalar Python code that numba compiles, cached.

From the sympy expressions of f and h (:func:`kalcal.core.nonlinear.symbolic_model`) and their
derivatives, five functions are printed (common subexpressions shared by sympy's ``cse``, functions of
:mod:`math`), each for one realization ``j`` of a tile of realizations laid out as structure of arrays
(realizations on the last axis, as :func:`kalcal.core.kernels.covariance_update` takes them)::

    f(x, u, dt, out, j)    x (d, m), u (m_in,), out (d, m)        out[:, j] = f(x[:, j], u, dt)
    F(x, u, dt, out, j)    out (d, d, m)                          out[:, :, j] = df/dx at x[:, j]
    h(x, data, out, j)     data (k,), out (p, m)                  out[:, j] = h(x[:, j], data)
    H(x, data, out, j)     out (p, d, m)                          out[:, :, j] = dh/dx at x[:, j]
    hH(x, data, out_h, out_H, j)                                  h and H at once, their common
                                                                  subexpressions (sines, roots) computed once

F and H write only their entries that are not identically zero (sympy's derivative is the number 0
whatever x, u and data): the caller's arrays hold zeros there from the start. The pattern of those
entries is printed beside them, ``F_nz`` (d, d) and ``H_nz`` (p, d) tuples of 0/1, so that a kernel (given them as arrays)
skips the products with a zero factor (a model whose state is kept or renewed, as a static pose's, has
an F of a few ones): adding an exact zero changes no sum, so the skipped products change no result.

A model's printed functions and the driver of a compiled kernel that calls them are written to a module
file named by the SHA-256 of its text, in the cache folder (``KALCAL_CACHE_DIR``, else
``~/.cache/kalcal/compiled``, else a folder under the system's temporary one), imported, and compiled by
numba with ``cache=True``: a second run of the same model (same text) loads the machine code from numba's
cache beside that file instead of compiling again (a few seconds). The text carries the digest of the
kernel module it calls (:mod:`kalcal.scenarios.nonlinear.kernel`), so a change of that module (or, by its
own cache stamp, of :mod:`kalcal.core.kernels`) names a new file and compiles anew.

Only models whose f and h sympy can take (the default Jacobians, ``"sympy"`` or ``"auto"`` without
explicit Jacobians) are printed; :func:`compilable` says why a model is not, and such a model keeps the
batched numpy path.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
from pathlib import Path

from kalcal.core.nonlinear import NonlinearModel, symbolic_model

__all__ = ["cache_dir", "compilable", "model_source", "load_generated"]


def compilable(model: NonlinearModel) -> str:
    """"" where the model's f, h and Jacobians can be printed as compiled code, else why not (the reason
    the caller reports when it keeps the numpy path)."""
    if model.f_jacobian is not None or model.h_jacobian is not None:
        return "the model gives explicit Jacobians (numpy functions), which cannot be compiled"
    if model.jacobian not in ("auto", "sympy"):
        return f"the model asks for {model.jacobian!r} Jacobians, not sympy's"
    try:
        symbolic_model(model)
    except Exception as error:  # any failure to trace on symbols: the numpy path, and why
        return f"f or h cannot be called on sympy symbols ({type(error).__name__}: {error})"
    return ""


def _printer():
    from sympy.printing.precedence import PRECEDENCE
    from sympy.printing.pycode import PythonCodePrinter

    class Printer(PythonCodePrinter):
        """Python's printer, with a power of half an odd integer (other than +-1/2, a root already) printed
        as a product with a root, b**(3/2) as (b*math.sqrt(b)): compiled, ``**`` of a float exponent is a
        call of libm's pow, about 6 ns a realization where the root and the product take 2 (an EKF of a
        normalized vector's Jacobian has one per call); the two agree to rounding."""

        def _print_Pow(self, expr, rational=False):
            e = expr.exp
            if e.is_Rational and e.q == 2 and abs(e.p) > 1:
                base = self.parenthesize(expr.base, PRECEDENCE["Pow"])
                k = (abs(e.p) - 1) // 2
                text = f"({base}*math.sqrt({base}))" if k == 1 else f"({base}**{k}*math.sqrt({base}))"
                return f"(1/{text})" if e.p < 0 else text
            return super()._print_Pow(expr, rational)

    return Printer({"fully_qualified_modules": True, "standard": "python3"})


def _function(name: str, args: str, prelude: list[str], expressions: list, targets: list[str]) -> list[str]:
    """One printed function: its inputs unpacked into local names, the shared subexpressions, the outputs."""
    import sympy

    printer = _printer()
    temporaries, reduced = sympy.cse(expressions, symbols=sympy.numbered_symbols("_t"), optimizations=None)
    lines = [
        "@numba.njit(cache=True, nogil=True, inline='always', error_model='numpy')",
        f"def {name}({args}):",
        *prelude,
    ]
    for symbol, value in temporaries:
        lines.append(f"    {symbol} = {printer.doprint(value)}")
    for target, value in zip(targets, reduced):
        lines.append(f"    {target} = float({printer.doprint(value)})")
    if len(lines) == 2 + len(prelude):
        lines.append("    pass")
    return lines


def model_source(model: NonlinearModel, prefix: str) -> str:
    """The four printed functions of a model (module docstring), their names starting with ``prefix``."""
    import sympy

    sym = symbolic_model(model)
    d, p = model.state_dim, model.measurement_dim
    x_prelude = [f"    {s} = x[{i}, j]" for i, s in enumerate(sym.x)]
    u_prelude = [f"    {s} = u[{i}]" for i, s in enumerate(sym.u)]
    data_prelude = [f"    {s} = data[{i}]" for i, s in enumerate(sym.data)]
    dt_prelude = [f"    {sym.dt} = dt"]
    f_jac = sympy.Matrix(list(sym.f)).jacobian(list(sym.x))
    h_jac = sympy.Matrix(list(sym.h)).jacobian(list(sym.x))
    lines: list[str] = []
    lines += _function(f"{prefix}_f", "x, u, dt, out, j", x_prelude + u_prelude + dt_prelude, list(sym.f),
                       [f"out[{i}, j]" for i in range(d)])
    f_nz = [[int(f_jac[i, c] != 0) for c in range(d)] for i in range(d)]
    h_nz = [[int(h_jac[i, c] != 0) for c in range(d)] for i in range(p)]
    f_entries = [(i, c) for i in range(d) for c in range(d) if f_nz[i][c]]
    h_entries = [(i, c) for i in range(p) for c in range(d) if h_nz[i][c]]
    lines += [""]
    lines += _function(f"{prefix}_F", "x, u, dt, out, j", x_prelude + u_prelude + dt_prelude,
                       [f_jac[i, c] for i, c in f_entries], [f"out[{i}, {c}, j]" for i, c in f_entries])
    lines += [""]
    lines += _function(f"{prefix}_h", "x, data, out, j", x_prelude + data_prelude, list(sym.h),
                       [f"out[{i}, j]" for i in range(p)])
    lines += [""]
    lines += _function(f"{prefix}_H", "x, data, out, j", x_prelude + data_prelude,
                       [h_jac[i, c] for i, c in h_entries], [f"out[{i}, {c}, j]" for i, c in h_entries])
    lines += [""]
    lines += _function(f"{prefix}_hH", "x, data, out_h, out_H, j", x_prelude + data_prelude,
                       list(sym.h) + [h_jac[i, c] for i, c in h_entries],
                       [f"out_h[{i}, j]" for i in range(p)] + [f"out_H[{i}, {c}, j]" for i, c in h_entries])
    lines += ["", f"{prefix}_F_nz = {_nested_tuple(f_nz)}", f"{prefix}_H_nz = {_nested_tuple(h_nz)}"]
    return "\n".join(lines) + "\n"


def _nested_tuple(rows: list[list[int]]) -> str:
    """A nested tuple's text (the pattern the caller reads from the generated module)."""
    return "(" + "".join("(" + "".join(f"{v}, " for v in row) + "), " for row in rows) + ")"


def cache_dir() -> Path:
    """The folder of the generated modules: ``KALCAL_CACHE_DIR``, else ``~/.cache/kalcal/compiled``, else a
    folder of the system's temporary one (where the home folder cannot be written)."""
    candidates = []
    if os.environ.get("KALCAL_CACHE_DIR"):
        candidates.append(Path(os.environ["KALCAL_CACHE_DIR"]))
    candidates.append(Path.home() / ".cache" / "kalcal" / "compiled")
    candidates.append(Path(tempfile.gettempdir()) / f"kalcal-compiled-{os.getuid() if hasattr(os, 'getuid') else 0}")
    for folder in candidates:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return folder
    raise OSError("no writable folder for the compiled models' modules (set KALCAL_CACHE_DIR)")


#: one import of a generated module at a time: the module is in sys.modules before its body has run, so a
#: second thread (the Monte Carlo's blocks ask for the kernel at once) would otherwise get it half made
_LOADING = threading.RLock()


def load_generated(text: str):
    """Write ``text`` as a module named by its digest in :func:`cache_dir` (once) and import it (one
    thread at a time: another thread waits for the module whole)."""
    with _LOADING:
        return _load_generated(text)


def _load_generated(text: str):
    digest = hashlib.sha256(text.encode()).hexdigest()[:24]
    name = f"kalcal_compiled_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    folder = cache_dir()
    path = folder / f"{name}.py"
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        # written beside and renamed: a process running at the same time never reads half a file
        handle, temporary = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(handle, "w", encoding="utf-8") as out:
            out.write(text)
        os.replace(temporary, path)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception:
        sys.modules.pop(name, None)
        raise
    return module
