"""A nonlinear model written as code: transition f, measurement h, additive noises, prior, and its Jacobians.

The model, one predict and one update per measurement time step ``dt``::

    x_k = f(x_{k-1}, u_k, dt) + w_k,      w_k ~ N(0, Q)        (k = 1..K)
    z_k = h(x_k, data_k) + v_k,           v_k ~ N(0, R)
    x_0 ~ N(x0, P0)

The first measurement is taken after one step (at time dt, not at time 0), as for
:class:`~kalcal.core.model.LinearGaussianModel` with one sample per update.

**Calling convention.** f and h act on a whole batch of realizations at once, never one by one (a Python
call per realization costs about a microsecond more than the arithmetic, 10 s at 10^5 realizations x 100
updates)::

    f(x, u, dt) -> (n, d)     x: (n, d) states; u: (m,) shared by the batch or (n, m), None when m = 0;
                              dt: float (s)
    h(x, data)  -> (n, p)     data: (k,) shared or (n, k), None when k = 0

u and data are known inputs of one update (a control, a beacon's position); their sizes m and k are the
model's ``input_dim`` and ``data_dim``. Write the nonlinear functions with :mod:`kalcal.core.xmath`
(``xm.sin``, ``xm.arctan2``, ``xm.stack``, ...), which dispatch to numpy, sympy or jax by their argument,
so that the same f and h give their own Jacobians; indexing (``x[:, 0]``) and arithmetic need nothing.

**Jacobians** F = df/dx (n, d, d) and H = dh/dx (n, p, d), by ``jacobian``:

- ``"sympy"``: f and h called once on symbols, differentiated, and lambdified to numpy functions of the
  batch's columns. Exact, and the fastest measured (benchmarks/bench_nonlinear.py, the range-bearing
  example at n = 10^5 on a shared 2-core machine: F 0.7 ms and H 1.0 ms, against 1.0 and 1.8 ms for
  jax's jit(vmap(jacfwd)) after 1.7 s of compiling, and 52 and 44 ms for checked central differences;
  sympy's derivation costs 0.4 s once).
- ``"jax"``: jax.jacfwd under vmap and jit (the optional extra ``kalcal[jax]``); f and h then run on
  float64 jax arrays (jax's x64 mode is switched on).
- ``"finite"``: central differences, checked: each Jacobian is computed with two steps (h_j and 4 h_j)
  and a disagreement beyond ``fd_rtol`` warns (``fd_check="warn"``) or raises (``"raise"``).
- ``"auto"`` (the default): explicit Jacobians where given (``f_jacobian``, ``h_jacobian``), else sympy;
  where f or h cannot be called on symbols (a numpy-only function), checked finite differences, and
  :attr:`NonlinearModel.jacobians` says so in its ``reason``.
"""

from __future__ import annotations

import importlib.util
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal, NamedTuple

import numpy as np

from kalcal.core.model import _as_matrix, check_covariance
from kalcal.errors import ConfigError
from kalcal.models.settings import SettingError, show

__all__ = [
    "JACOBIAN_METHODS",
    "Jacobians",
    "NonlinearModel",
    "NonlinearModels",
    "finite_difference_jacobian",
    "load_nonlinear_model",
]

JacobianMethod = Literal["auto", "sympy", "jax", "finite"]
JACOBIAN_METHODS: tuple[str, ...] = ("auto", "sympy", "jax", "finite")

#: The relative step of central differences, eps^(1/3): it balances the truncation error (h^2) against
#: the rounding error (eps / h), for a relative error near eps^(2/3) ~ 4e-11 on a smooth function.
FD_STEP = float(np.finfo(float).eps ** (1.0 / 3.0))
#: The check's larger step, as a multiple of the first: its truncation error is 16 times the first's, so
#: agreement within ``fd_rtol`` bounds the first's error well below it.
FD_CHECK_FACTOR = 4.0


class Jacobians(NamedTuple):
    """A model's two Jacobian functions and how they were obtained."""

    f: Callable[..., np.ndarray]  #: F(x, u, dt) -> (n, d, d)
    h: Callable[..., np.ndarray]  #: H(x, data) -> (n, p, d)
    method: str  #: "explicit", "sympy", "jax" or "finite"
    reason: str  #: why this method ("" where it was asked for)


def _names(name: str, value, size: int) -> tuple[str, ...]:
    names = tuple(str(v) for v in value)
    if len(names) != size:
        raise SettingError(name, f"{size} names", show(list(names)))
    return names


@dataclass(frozen=True, eq=False)
class NonlinearModel:
    """A nonlinear model with additive Gaussian noises, for a batch of realizations (the module's docstring).

    Attributes
    ----------
    f : callable
        Transition f(x, u, dt): x (n, d), u (m,) or (n, m) or None, dt (s) -> (n, d).
    h : callable
        Measurement h(x, data): x (n, d), data (k,) or (n, k) or None -> (n, p).
    q : ndarray, shape (d, d)
        Process-noise covariance over one step dt, additive, in the states' units squared.
    r : ndarray, shape (p, p)
        Measurement-noise covariance, in the measurements' units squared, positive definite.
    x0 : ndarray, shape (d,)
        Prior mean of the state at time 0.
    p0 : ndarray, shape (d, d)
        Prior covariance of the state at time 0.
    dt : float
        The time step between two measurements (s), passed to f.
    state_names, state_units : tuple of str, length d
    measurement_names, measurement_units : tuple of str, length p
    input_dim : int
        m, the size of u (0: f takes u = None).
    data_dim : int
        k, the size of data (0: h takes data = None).
    jacobian : {"auto", "sympy", "jax", "finite"}
        How F and H are obtained where ``f_jacobian`` / ``h_jacobian`` are not given.
    f_jacobian, h_jacobian : callable or None
        Explicit Jacobians F(x, u, dt) -> (n, d, d) and H(x, data) -> (n, p, d); where one is given
        (with ``jacobian="auto"``) it is used, the other derived.
    fd_check : {"warn", "raise"}
        What a finite-difference Jacobian does when its two steps disagree.
    fd_rtol : float
        Their tolerance, relative to the largest entry of the row, each column scaled by its state's step
        scale (dimensionless).
    """

    f: Callable[..., np.ndarray]
    h: Callable[..., np.ndarray]
    q: np.ndarray
    r: np.ndarray
    x0: np.ndarray
    p0: np.ndarray
    dt: float
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    measurement_names: tuple[str, ...]
    measurement_units: tuple[str, ...]
    input_dim: int = 0
    data_dim: int = 0
    jacobian: JacobianMethod = "auto"
    f_jacobian: Callable[..., np.ndarray] | None = None
    h_jacobian: Callable[..., np.ndarray] | None = None
    fd_check: Literal["warn", "raise"] = "warn"
    fd_rtol: float = 1e-5
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("f", "h"):
            if not callable(getattr(self, name)):
                raise SettingError(name, "a function", show(getattr(self, name)))
        for name in ("f_jacobian", "h_jacobian"):
            value = getattr(self, name)
            if value is not None and not callable(value):
                raise SettingError(name, "a function or None", show(value))
        x0 = np.array(self.x0, dtype=float)
        if x0.ndim != 1 or x0.size == 0 or not np.all(np.isfinite(x0)):
            raise SettingError("x0", "a finite vector", show(x0))
        x0.setflags(write=False)
        d = x0.size
        p0 = _as_matrix("p0", self.p0, (d, d))
        q = _as_matrix("q", self.q, (d, d))
        check_covariance("p0", p0)
        check_covariance("q", q)
        r = _as_matrix("r", self.r)
        p = r.shape[0]
        if r.shape != (p, p) or p == 0:
            raise SettingError("r", "a square matrix", f"shape {r.shape}")
        check_covariance("r", r)
        if np.linalg.eigvalsh(r).min() <= 0.0:
            raise SettingError("r", "a positive definite covariance", show(r))
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise SettingError("dt", "a positive time step (s)", show(self.dt))
        for name in ("input_dim", "data_dim"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise SettingError(name, "a non-negative integer", show(value))
        if self.jacobian not in JACOBIAN_METHODS:
            raise SettingError("jacobian", f"one of {', '.join(JACOBIAN_METHODS)}", show(self.jacobian))
        if self.fd_check not in ("warn", "raise"):
            raise SettingError("fd_check", "'warn' or 'raise'", show(self.fd_check))
        if not (np.isfinite(self.fd_rtol) and self.fd_rtol > 0):
            raise SettingError("fd_rtol", "a positive number", show(self.fd_rtol))
        object.__setattr__(self, "x0", x0)
        object.__setattr__(self, "p0", p0)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "r", r)
        object.__setattr__(self, "dt", float(self.dt))
        object.__setattr__(self, "input_dim", int(self.input_dim))
        object.__setattr__(self, "data_dim", int(self.data_dim))
        object.__setattr__(self, "state_names", _names("state_names", self.state_names, d))
        object.__setattr__(self, "state_units", _names("state_units", self.state_units, d))
        object.__setattr__(self, "measurement_names", _names("measurement_names", self.measurement_names, p))
        object.__setattr__(self, "measurement_units", _names("measurement_units", self.measurement_units, p))

    @property
    def state_dim(self) -> int:
        """d, the number of states."""
        return self.x0.size

    @property
    def measurement_dim(self) -> int:
        """p, the number of measurement components."""
        return self.r.shape[0]

    # -- calls on a batch ---------------------------------------------------------------------------------

    def transition(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """f(x, u, dt) of a batch, checked: x (n, d) -> (n, d)."""
        out = np.asarray(self.f(x, self._input(u), self.dt), dtype=float)
        if out.shape != x.shape:
            raise ConfigError(f"f: expected an output of shape {x.shape} for states {x.shape}, got {out.shape}")
        return out

    def measure(self, x: np.ndarray, data: np.ndarray | None = None) -> np.ndarray:
        """h(x, data) of a batch, checked: x (n, d) -> (n, p)."""
        out = np.asarray(self.h(x, self._data(data)), dtype=float)
        expected = (x.shape[0], self.measurement_dim)
        if out.shape != expected:
            raise ConfigError(f"h: expected an output of shape {expected} for states {x.shape}, got {out.shape}")
        return out

    def transition_jacobian(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """F = df/dx at each state of the batch: x (n, d) -> (n, d, d)."""
        out = np.asarray(self.jacobians.f(x, self._input(u), self.dt), dtype=float)
        d = self.state_dim
        return np.broadcast_to(out, (x.shape[0], d, d))

    def measurement_jacobian(self, x: np.ndarray, data: np.ndarray | None = None) -> np.ndarray:
        """H = dh/dx at each state of the batch: x (n, d) -> (n, p, d)."""
        out = np.asarray(self.jacobians.h(x, self._data(data)), dtype=float)
        return np.broadcast_to(out, (x.shape[0], self.measurement_dim, self.state_dim))

    def _input(self, u):
        return _known("u", u, self.input_dim)

    def _data(self, data):
        return _known("data", data, self.data_dim)

    # -- Jacobians ------------------------------------------------------------------------------------------

    @property
    def jacobians(self) -> Jacobians:
        """The Jacobian functions, derived once on first use (sympy's derivation takes about a second)."""
        if "jacobians" not in self._cache:
            self._cache["jacobians"] = self._derive_jacobians()
        return self._cache["jacobians"]

    def _derive_jacobians(self) -> Jacobians:
        method, reason = self.jacobian, ""
        if method == "auto":
            if self.f_jacobian is not None and self.h_jacobian is not None:
                return Jacobians(self.f_jacobian, self.h_jacobian, "explicit", "given")
            try:
                derived = symbolic_jacobians(self)
            except Exception as error:  # any failure to trace on symbols falls back, and says why
                method = "finite"
                reason = f"f or h cannot be called on sympy symbols ({type(error).__name__}: {error})"
                derived = finite_difference_jacobians(self)
            else:
                method, reason = "sympy", "the default"
        elif method == "sympy":
            derived = symbolic_jacobians(self)
        elif method == "jax":
            derived = jax_jacobians(self)
        else:
            derived = finite_difference_jacobians(self)
        f_jac = self.f_jacobian if self.f_jacobian is not None else derived[0]
        h_jac = self.h_jacobian if self.h_jacobian is not None else derived[1]
        return Jacobians(f_jac, h_jac, method, reason)


def _known(name: str, value, size: int):
    """u or data as an array (size,) or (n, size), or None where the model takes none."""
    if size == 0:
        return None
    if value is None:
        raise ConfigError(f"{name}: the model takes {size} values per update, got none")
    array = np.asarray(value, dtype=float)
    if array.shape[-1:] != (size,) or array.ndim > 2:
        raise ConfigError(f"{name}: expected shape ({size},) or (n, {size}), got {array.shape}")
    return array


# -- symbolic (sympy) ---------------------------------------------------------------------------------------


def _columns(array, size: int) -> list:
    """The columns of (size,) or (n, size) as scalars or (n,) arrays (lambdified functions take them)."""
    if size == 0:
        return []
    return [array[..., i] for i in range(size)]


def _lambdified_jacobian(expressions: np.ndarray, variables, arguments, rows: int, cols: int):
    """A numpy function of the arguments' columns that fills an (n, rows, cols) Jacobian from sympy entries."""
    import sympy

    matrix = sympy.Matrix(rows, 1, list(expressions)).jacobian(list(variables))
    nonzero = [(i, j) for i in range(rows) for j in range(cols) if matrix[i, j] != 0]
    function = sympy.lambdify(list(arguments), [matrix[i, j] for i, j in nonzero], modules="numpy", cse=True)

    def jacobian(columns: list, n: int) -> np.ndarray:
        out = np.zeros((n, rows, cols))
        if nonzero:
            for (i, j), value in zip(nonzero, function(*columns)):
                out[:, i, j] = value  # a constant entry broadcasts over the batch
        return out

    return jacobian, matrix


class SymbolicModel(NamedTuple):
    """f and h of a model called once on sympy symbols: the expressions its Jacobians and its compiled
    code (:mod:`kalcal.core.nonlinear_codegen`) are derived from."""

    x: tuple  #: the state's symbols x0..x{d-1}
    u: tuple  #: the input's symbols u0..u{m-1} (empty where m = 0)
    data: tuple  #: the data's symbols data0..data{k-1} (empty where k = 0)
    dt: Any  #: the time step's symbol
    f: tuple  #: f's d expressions
    h: tuple  #: h's p expressions


def symbolic_model(model: NonlinearModel) -> SymbolicModel:
    """f and h called on symbols (once per model, kept); raises where they cannot take symbols."""
    if "symbolic" in model._cache:
        return model._cache["symbolic"]
    import sympy

    d, p, m, k = model.state_dim, model.measurement_dim, model.input_dim, model.data_dim
    xs = sympy.symbols(f"x0:{d}", real=True)
    us = sympy.symbols(f"u0:{m}", real=True) if m else ()
    ds = sympy.symbols(f"data0:{k}", real=True) if k else ()
    dt = sympy.Symbol("dt", positive=True)
    x_sym = np.array(xs, dtype=object)[None, :]
    u_sym = np.array(us, dtype=object)[None, :] if m else None
    data_sym = np.array(ds, dtype=object)[None, :] if k else None
    f_out = np.asarray(model.f(x_sym, u_sym, dt), dtype=object)
    h_out = np.asarray(model.h(x_sym, data_sym), dtype=object)
    if f_out.shape != (1, d) or h_out.shape != (1, p):
        raise ConfigError(f"f, h: expected outputs of shapes (1, {d}) and (1, {p}) on symbols, got {f_out.shape}, {h_out.shape}")
    out = SymbolicModel(tuple(xs), tuple(us), tuple(ds), dt,
                        tuple(sympy.sympify(e) for e in f_out[0]), tuple(sympy.sympify(e) for e in h_out[0]))
    model._cache["symbolic"] = out
    return out


def symbolic_jacobians(model: NonlinearModel) -> tuple[Callable, Callable]:
    """F and H by sympy: f and h called once on symbols, differentiated, lambdified to numpy.

    Returns
    -------
    f_jacobian : callable, F(x, u, dt) -> (n, d, d)
    h_jacobian : callable, H(x, data) -> (n, p, d)
    """
    d, p, m, k = model.state_dim, model.measurement_dim, model.input_dim, model.data_dim
    xs, us, ds, dt, f_out, h_out = symbolic_model(model)
    fill_f, _ = _lambdified_jacobian(f_out, xs, (*xs, *us, dt), d, d)
    fill_h, _ = _lambdified_jacobian(h_out, xs, (*xs, *ds), p, d)

    def f_jacobian(x, u, step):
        return fill_f([*_columns(x, d), *_columns(u, m), step], x.shape[0])

    def h_jacobian(x, data):
        return fill_h([*_columns(x, d), *_columns(data, k)], x.shape[0])

    return f_jacobian, h_jacobian


# -- automatic (jax, optional) ------------------------------------------------------------------------------


def jax_jacobians(model: NonlinearModel) -> tuple[Callable, Callable]:
    """F and H by jax: jit(vmap(jacfwd)) of f and h on one realization, in float64.

    Needs the optional extra (``pip install kalcal[jax]``); switches jax's x64 mode on.
    """
    try:
        import jax
        import jax.numpy as jnp
    except ImportError as error:
        raise ConfigError("jacobian: 'jax' needs the optional extra: pip install 'kalcal[jax]'") from error
    jax.config.update("jax_enable_x64", True)
    m, k = model.input_dim, model.data_dim

    def f_one(x, u, dt):
        return model.f(x[None, :], None if m == 0 else u[None, :], dt)[0]

    def h_one(x, data):
        return model.h(x[None, :], None if k == 0 else data[None, :])[0]

    f_batch = jax.jit(jax.vmap(jax.jacfwd(f_one), in_axes=(0, 0, None)))
    h_batch = jax.jit(jax.vmap(jax.jacfwd(h_one), in_axes=(0, 0)))

    def per_realization(value, size, n):
        if size == 0:
            return jnp.zeros((n, 0))
        return jnp.broadcast_to(jnp.asarray(value, dtype=jnp.float64), (n, size))

    def f_jacobian(x, u, dt):
        n = x.shape[0]
        return np.asarray(f_batch(jnp.asarray(x), per_realization(u, m, n), dt))

    def h_jacobian(x, data):
        n = x.shape[0]
        return np.asarray(h_batch(jnp.asarray(x), per_realization(data, k, n)))

    return f_jacobian, h_jacobian


# -- finite differences (checked) ---------------------------------------------------------------------------


def finite_difference_jacobian(
    function: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    scale: np.ndarray,
    *,
    rtol: float = 1e-5,
    check: Literal["warn", "raise"] = "warn",
    name: str = "function",
) -> np.ndarray:
    """The Jacobian of a batched function by central differences, checked against a second step.

    J[:, :, j] = (g(x + h_j e_j) - g(x - h_j e_j)) / (2 h_j), with h_j = eps^(1/3) max(|x_j|, s_j), s_j the
    state's scale (a prior standard deviation). The same with 4 h_j must agree: |J_h - J_4h|_ij s_j <=
    rtol max_j' |J_h|_ij' s_j' for every row i (entries scaled to the output's units); where it does not
    (a kink, a discontinuity, a function too rough for the step), a warning or a :class:`ConfigError`
    names the worst realization and entry.

    Parameters
    ----------
    function : callable, (n, d) -> (n, o)
    x : ndarray, shape (n, d)
    scale : ndarray, shape (d,), positive, in the states' units
    rtol : float
    check : {"warn", "raise"}
    name : str
        Quoted in the warning or error.

    Returns
    -------
    ndarray, shape (n, o, d)
    """
    x = np.asarray(x, dtype=float)
    step = FD_STEP * np.maximum(np.abs(x), scale)

    def central(steps: np.ndarray) -> np.ndarray:
        columns = []
        for j in range(x.shape[1]):
            plus, minus = x.copy(), x.copy()
            plus[:, j] += steps[:, j]
            minus[:, j] -= steps[:, j]
            # the step actually taken (x + h - x), so that the rounding of x + h cancels
            taken = plus[:, j] - minus[:, j]
            columns.append((function(plus) - function(minus)) / taken[:, None])
        return np.stack(columns, axis=-1)

    jac = central(step)
    wide = central(FD_CHECK_FACTOR * step)
    scaled = np.abs(jac - wide) * scale
    row_scale = np.max(np.abs(jac) * scale, axis=-1, keepdims=True)
    excess = scaled - rtol * row_scale
    if np.any(excess > 0) or not np.all(np.isfinite(jac)):
        bad = np.argwhere(~(excess <= 0))[0]
        i = int(bad[0])
        message = (
            f"{name}: central differences disagree between steps h and {FD_CHECK_FACTOR:g} h at realization {i}, "
            f"entry {tuple(int(v) for v in bad[1:])}: {jac[tuple(bad)]:.6g} against {wide[tuple(bad)]:.6g} "
            f"(tolerance {rtol:g} of the row's largest scaled entry); give the Jacobian explicitly or use "
            f"jacobian='sympy'"
        )
        if check == "raise":
            raise ConfigError(message)
        warnings.warn(message, RuntimeWarning, stacklevel=3)
    return jac


def finite_difference_jacobians(model: NonlinearModel) -> tuple[Callable, Callable]:
    """F and H by checked central differences (:func:`finite_difference_jacobian`), steps scaled by sqrt(diag P0)."""
    prior_std = np.sqrt(np.diag(model.p0))
    # a state with no prior spread still needs a scale for its step: its mean's size, or 1 in its unit
    scale = np.where(prior_std > 0, prior_std, np.maximum(np.abs(model.x0), 1.0))
    options = {"rtol": model.fd_rtol, "check": model.fd_check}

    def f_jacobian(x, u, dt):
        return finite_difference_jacobian(lambda s: model.f(s, u, dt), x, scale, name="f", **options)

    def h_jacobian(x, data):
        return finite_difference_jacobian(lambda s: model.h(s, data), x, scale, name="h", **options)

    return f_jacobian, h_jacobian


# -- the Python file ------------------------------------------------------------------------------------------


class NonlinearModels(NamedTuple):
    """The truth's and the filter's model read from a Python file (the same object where it defines MODEL)."""

    truth: NonlinearModel
    filter: NonlinearModel
    source: str  #: the file's path
    module: Any = None  #: the module the file defines (its DATA, INPUTS, N_UPDATES), None for objects


def load_nonlinear_model(path: str | Path) -> NonlinearModels:
    """Read a model written as a Python file: a module defining ``MODEL``, or ``truth`` and ``filter``.

    Each must be a :class:`NonlinearModel`. ``MODEL`` serves as both truth and filter; ``truth`` and
    ``filter`` are the simulation's and the estimator's models (the filter's may differ from the truth's). The module runs as Python code: load only files you trust.

    Raises
    ------
    ConfigError
        One line naming the file: no such file, the module failed to import (its error), neither
        ``MODEL`` nor both ``truth`` and ``filter`` defined, or a name bound to something else.
    """
    source = str(path)
    file = Path(path)
    if not file.is_file():
        raise ConfigError(f"{source}: no such file")
    name = f"kalcal_nonlinear_model_{abs(hash(str(file.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, file)
    if spec is None or spec.loader is None:
        raise ConfigError(f"{source}: not a Python module (expected a .py file)")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look a module up by name
    try:
        spec.loader.exec_module(module)
    except Exception as error:
        sys.modules.pop(name, None)
        detail = str(error).splitlines()[0] if str(error) else ""
        raise ConfigError(f"{source}: the module failed to run: {type(error).__name__}: {detail}") from error

    def get(attribute: str) -> NonlinearModel:
        value = getattr(module, attribute)
        if not isinstance(value, NonlinearModel):
            raise ConfigError(f"{source}: {attribute}: expected a kalcal NonlinearModel, got {type(value).__name__}")
        return value

    if hasattr(module, "MODEL"):
        model = get("MODEL")
        return NonlinearModels(model, model, source, module)
    missing = [attribute for attribute in ("truth", "filter") if not hasattr(module, attribute)]
    if missing:
        raise ConfigError(
            f"{source}: defines neither MODEL nor {' and '.join(missing) if len(missing) == 2 else missing[0]} "
            f"(a nonlinear model defines MODEL = NonlinearModel(...), or truth and filter)"
        )
    return NonlinearModels(get("truth"), get("filter"), source, module)

