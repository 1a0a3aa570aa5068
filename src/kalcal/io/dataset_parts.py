"""A Dataset held as numpy arrays (dimensions, values, attributes), made an ``xarray.Dataset`` only when asked.

The verify job builds its statistics (``stats.nc``, ``stats_long.nc``) as :class:`DatasetParts`: writing
them (:func:`kalcal.io.statistics.write_statistics`) and sending them to the report's figures need no
xarray, whose import (pandas with it) and the Dask check of its index variables cost about half a
second of every ``kalcal verify`` (``benchmarks/bench_job.py``); the figures draw the parts as they are.
:meth:`DatasetParts.to_xarray` gives the Dataset itself, as :func:`kalcal.verify` returns it.

The parts answer the few questions the job asks of its statistics as xarray would (``variables`` in
xarray's order, ``coords``, ``data_vars``, ``sizes``, ``dims``, ``attrs``, ``parts["time"].values``,
``name in parts``); anything else is asked of :meth:`DatasetParts.to_xarray`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import xarray as xr


@dataclass(frozen=True, eq=False)
class Part:
    """One variable: its dimension names, values (numbers or strings) and attributes."""

    dims: tuple[str, ...]
    values: np.ndarray
    attrs: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of(cls, dims: str | tuple[str, ...], values, attrs: dict[str, Any] | None = None) -> Part:
        """A part from a dimension name or names and anything ``np.asarray`` takes."""
        return cls((dims,) if isinstance(dims, str) else tuple(dims), np.asarray(values), dict(attrs or {}))

    @property
    def encoding(self) -> dict[str, Any]:
        """No NetCDF encoding of its own (xarray's ``Variable.encoding`` of a variable built in memory)."""
        return {}

    @property
    def dtype(self) -> np.dtype:
        return self.values.dtype

    @property
    def shape(self) -> tuple[int, ...]:
        return self.values.shape


@dataclass(frozen=True, eq=False)
class DatasetParts:
    """A Dataset's data variables and coordinates (name -> :class:`Part`, in order) and global attributes."""

    data_vars: dict[str, Part]
    coords: dict[str, Part]
    attrs: dict[str, Any] = field(default_factory=dict)

    @property
    def variables(self) -> dict[str, Part]:
        """Every variable in xarray's order: the data variables, then the coordinates."""
        return {**self.data_vars, **self.coords}

    @property
    def sizes(self) -> dict[str, int]:
        """Each dimension's length, in the order of first use."""
        sizes: dict[str, int] = {}
        for name, part in self.variables.items():
            if len(part.dims) != part.values.ndim:
                raise ValueError(f"{name}: {len(part.dims)} dimension names for {part.values.ndim} dimensions")
            for dim, length in zip(part.dims, part.values.shape):
                if sizes.setdefault(dim, length) != length:
                    raise ValueError(f"{name}: dimension {dim} has length {length}, elsewhere {sizes[dim]}")
        return sizes

    @property
    def dims(self) -> tuple[str, ...]:
        return tuple(self.sizes)

    def __getitem__(self, name: str) -> Part:
        return self.variables[name]

    def __contains__(self, name: object) -> bool:
        return name in self.data_vars or name in self.coords

    def to_xarray(self) -> xr.Dataset:
        """The ``xarray.Dataset`` of these parts: a new Dataset at each call, over the parts' own arrays (not
        copied: changing its values in place changes the parts)."""
        import xarray as xr

        self.sizes  # noqa: B018 (the dimensions' lengths agree, or a ValueError names the variable)
        return xr.Dataset(
            {name: _variable(part) for name, part in self.data_vars.items()},
            coords={name: _variable(part) for name, part in self.coords.items()},
            attrs=dict(self.attrs),
        )


def as_xarray(dataset):
    """``dataset.to_xarray()`` for :class:`DatasetParts`; anything else (a Dataset, None) as it is."""
    return dataset.to_xarray() if isinstance(dataset, DatasetParts) else dataset


def _variable(part: Part):
    """``xr.Variable(dims, values, attrs)`` for numbers or strings without its check for Dask arrays (which
    imports dask.array, most of a second, for nothing); anything else takes xarray's own conversions."""
    import xarray as xr

    attrs = dict(part.attrs)
    if part.values.dtype.kind not in "fU":
        return xr.Variable(part.dims, part.values, attrs)
    return xr.Variable(part.dims, part.values, attrs, fastpath=True)
