"""The functions a nonlinear model's f and h are written with, so one definition serves numpy, sympy and jax.

A model's transition and measurement (:class:`kalcal.core.nonlinear.NonlinearModel`) are called on a
batch of numeric states to filter, on symbols to derive their Jacobians (sympy), or on jax's traced
arrays (the optional automatic differentiation). numpy's own functions fail on the last two, so a model
writes its nonlinear functions with these, which dispatch on their argument::

    from kalcal.core import xmath as xm

    def h(x, data):
        dx, dy = x[:, 0] - data[..., 0], x[:, 1] - data[..., 1]
        return xm.stack([xm.hypot(dx, dy), xm.arctan2(dy, dx)])

Arithmetic (``+ - * / **``), indexing and slicing need nothing: they work on every kind of array.
Dispatch: an array of dtype object or a sympy expression goes to sympy (element by element), a jax array
or tracer to ``jax.numpy``, anything else to numpy. sympy and jax are imported only when such an
argument arrives, so a numeric run imports neither.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = [
    "sin",
    "cos",
    "tan",
    "arcsin",
    "arccos",
    "arctan",
    "arctan2",
    "sinh",
    "cosh",
    "tanh",
    "exp",
    "log",
    "sqrt",
    "hypot",
    "abs",
    "stack",
]


def _backend(*args: Any) -> str:
    """"sympy", "jax" or "numpy": the kind of the first argument that is not a plain number or numpy array."""
    for arg in args:
        if isinstance(arg, np.ndarray):
            if arg.dtype == object:
                return "sympy"
            continue
        module = type(arg).__module__ or ""
        if module.startswith("sympy"):
            return "sympy"
        if module.startswith(("jax", "jaxlib")):
            return "jax"
    return "numpy"


def _sympy_elementwise(function, *args):
    """Apply a sympy function element by element, keeping the arrays' shapes (dtype object)."""
    return np.vectorize(function, otypes=[object])(*args)


def _dispatch(numpy_name: str, sympy_name: str):
    def apply(*args):
        kind = _backend(*args)
        if kind == "sympy":
            import sympy

            return _sympy_elementwise(getattr(sympy, sympy_name), *args)
        if kind == "jax":
            import jax.numpy as jnp

            return getattr(jnp, numpy_name)(*args)
        return getattr(np, numpy_name)(*args)

    apply.__name__ = numpy_name
    apply.__doc__ = f"numpy.{numpy_name}, sympy.{sympy_name} or jax.numpy.{numpy_name}, by the argument's kind."
    return apply


sin = _dispatch("sin", "sin")
cos = _dispatch("cos", "cos")
tan = _dispatch("tan", "tan")
arcsin = _dispatch("arcsin", "asin")
arccos = _dispatch("arccos", "acos")
arctan = _dispatch("arctan", "atan")
sinh = _dispatch("sinh", "sinh")
cosh = _dispatch("cosh", "cosh")
tanh = _dispatch("tanh", "tanh")
exp = _dispatch("exp", "exp")
log = _dispatch("log", "log")
sqrt = _dispatch("sqrt", "sqrt")
abs = _dispatch("abs", "Abs")  # noqa: A001 - the numpy name, on purpose


def arctan2(y, x):
    """The angle of (x, y) in (-pi, pi] (rad): numpy.arctan2, sympy.atan2 or jax.numpy.arctan2."""
    kind = _backend(y, x)
    if kind == "sympy":
        import sympy

        return _sympy_elementwise(sympy.atan2, y, x)
    if kind == "jax":
        import jax.numpy as jnp

        return jnp.arctan2(y, x)
    return np.arctan2(y, x)


def hypot(x, y):
    """sqrt(x^2 + y^2): numpy.hypot (no overflow), its sympy expression, or jax.numpy.hypot."""
    kind = _backend(x, y)
    if kind == "sympy":
        import sympy

        return _sympy_elementwise(lambda a, b: sympy.sqrt(a * a + b * b), x, y)
    if kind == "jax":
        import jax.numpy as jnp

        return jnp.hypot(x, y)
    return np.hypot(x, y)


def stack(columns: Sequence[Any], axis: int = -1):
    """The columns side by side on a new last axis: (n,) each -> (n, len(columns)).

    A column that is a plain number (a constant component) is broadcast to the others' shape.
    """
    kind = _backend(*columns)
    if kind == "jax":
        import jax.numpy as jnp

        arrays = [jnp.asarray(c) for c in columns]
        shape = jnp.broadcast_shapes(*(a.shape for a in arrays))
        return jnp.stack([jnp.broadcast_to(a, shape) for a in arrays], axis=axis)
    dtype = object if kind == "sympy" else float
    arrays = [np.asarray(c, dtype=dtype) for c in columns]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    return np.stack([np.broadcast_to(a, shape) for a in arrays], axis=axis)
