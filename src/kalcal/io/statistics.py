"""Ensemble statistics to and from NetCDF (``stats.nc``): the Dataset of :mod:`kalcal.verification.dataset`.

Dimensions: ``time`` (K update times, s), ``state``/``state2`` (d), ``measurement``/``measurement2`` (p),
and ``time2`` (a second copy of ``time``, always there; ``residual_second_moment``, the
residual correlation over pairs of updates, runs over it where the run kept the pairs). Written as
NetCDF3 through scipy, so no extra library is needed to read it: ``xarray.open_dataset("stats.nc")``.

:func:`load_statistics` reads such a file back as numpy parts without xarray, as the report does.

The Datasets kalcal builds (float variables, string labels, number and string attributes), as an
``xarray.Dataset`` or as the :class:`kalcal.io.dataset_parts.DatasetParts` the verify job keeps, are
written straight through ``scipy.io.netcdf_file``, byte for byte the file
``Dataset.to_netcdf(engine="scipy")`` writes: that call looks for a Dask scheduler on every write, which
imports ``dask.array`` and ``dask.distributed`` (about a second) into a job that uses neither, and parts
are written without loading xarray at all. Any other Dataset goes through ``to_netcdf`` itself.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.errors import DataError
from kalcal.io.dataset_parts import DatasetParts, Part, as_xarray

if TYPE_CHECKING:
    import xarray as xr

#: NetCDF3 with 64-bit offsets, as ``to_netcdf(engine="scipy")`` writes by default
_VERSION = 2

#: what scipy's NetCDF reader (and xarray's decoding over it) raises on a file cut short or corrupt: in
#: the header an IndexError or a struct.error, a KeyError for a bad type code, a MemoryError or
#: OverflowError for a huge count, a ValueError for short data, a LookupError for a bad encoding, an
#: AttributeError or TypeError for an attribute of the wrong type (the nets hold the reading alone)
_UNREADABLE = (OSError, ValueError, TypeError, LookupError, MemoryError, OverflowError, AttributeError, struct.error,
               EOFError)  # fmt: skip


def write_statistics(path: str | Path, dataset: xr.Dataset | DatasetParts) -> Path:
    """Write the Dataset (or its parts) as NetCDF3: the bytes of ``dataset.to_netcdf(path, engine="scipy")``
    (of ``parts.to_xarray().to_netcdf(...)``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    encoded = _encode(dataset)
    if encoded is None:  # not a layout the direct writer knows: xarray's own writer
        as_xarray(dataset).to_netcdf(path, engine="scipy")
    else:
        _write(path, *encoded)
    return path


def read_statistics(path: str | Path) -> xr.Dataset:
    """Read a ``stats.nc`` written by :func:`write_statistics` (fully loaded, file closed)."""
    import xarray as xr

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such statistics file")
    try:
        with xr.open_dataset(path, engine="scipy") as dataset:
            return dataset.load()
    except _UNREADABLE as exc:
        raise DataError(f"{path}: not a kalcal statistics file ({type(exc).__name__}: {exc})") from None


def load_statistics(path: str | Path) -> DatasetParts | xr.Dataset:
    """Read a statistics file as :class:`DatasetParts` (numbers as float64, labels as str arrays, bytes
    attributes as str: the values ``read_statistics`` gives), straight through ``scipy.io.netcdf_file``
    and without xarray, where it holds only what :func:`write_statistics` writes; any other file as
    :func:`read_statistics`'s Dataset. The report reads a run's files this way: xarray, pandas and the
    Dask check of xarray's variables were about a second of ``kalcal report``, in the job and again in its
    figure process, which unpickles what it is sent."""
    from scipy.io import netcdf_file

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such statistics file")
    try:
        file = netcdf_file(path, mode="r", mmap=False)  # the header and, without mmap, every variable's data
    except _UNREADABLE as exc:
        raise DataError(f"{path}: not a kalcal statistics file ({type(exc).__name__}: {exc})") from None
    with file:  # decoded outside the net: an error of the decoder's own is not the file's
        try:
            parts = _decoded(file)
        except UnicodeDecodeError:  # attributes or labels not UTF-8: xarray's to read (it replaces bad bytes)
            parts = None
    return parts if parts is not None else read_statistics(path)


#: variable attributes that xarray's CF decoding would act on, beyond those the writer uses
_DECODED_BY_XARRAY = {"missing_value", "scale_factor", "add_offset", "calendar", "_Unsigned", "dtype", "bounds"}
#: units that some xarray releases decode into timedeltas (kalcal writes time in "s")
_TIME_UNITS = {"days", "hours", "minutes", "seconds", "milliseconds", "microseconds", "nanoseconds"}


def _decoded(file) -> DatasetParts | None:
    """The parts of an open NetCDF3 file as :func:`write_statistics` writes it, None for anything else;
    UnicodeDecodeError where an attribute or a label is not UTF-8."""
    if "coordinates" in file._attributes:  # labels on no variable: xarray's global attribute, its to decode
        return None
    data_vars: dict[str, Part] = {}
    coords: dict[str, Part] = {}
    labels: set[str] = set()
    attributes = {str(key): _value(value) for key, value in file._attributes.items()}
    for name, variable in file.variables.items():
        attrs = {key: _value(value) for key, value in variable._attributes.items()}
        dims = tuple(variable.dimensions)
        data = variable.data
        units = str(attrs.get("units", ""))
        if _DECODED_BY_XARRAY & set(attrs) or " since " in units or units in _TIME_UNITS:
            return None
        over = attrs.pop("coordinates", "")
        if not isinstance(over, str):
            return None
        labels.update(over.split())
        fill = attrs.pop("_FillValue", None)
        if data.dtype == ">f8" and isinstance(fill, float) and np.isnan(fill):  # the writer's floats
            values = np.asarray(data, dtype=np.float64)
        elif data.dtype == "S1" and attrs.pop("_Encoding", None) == "utf-8" and dims and dims[-1].startswith("string"):
            if fill is not None:
                return None
            width = data.shape[-1]
            joined = np.ascontiguousarray(data).view(f"S{width}").reshape(data.shape[:-1])
            values = np.array([item.decode("utf-8") for item in joined.ravel()], dtype=str).reshape(joined.shape)
            dims = dims[:-1]
        else:
            return None
        (coords if dims == (name,) else data_vars)[name] = Part(dims, values, attrs)
    for label in labels:
        if label not in data_vars:
            return None
        coords[label] = data_vars.pop(label)
    coords = {name: coords[name] for name in file.variables if name in coords}  # the file's order, as xarray's
    return DatasetParts(data_vars, coords, attributes)


def _value(value: Any) -> Any:
    """An attribute as xarray gives it: bytes as str, anything else as scipy read it."""
    return value.decode("utf-8") if isinstance(value, bytes) else value


class _Unsupported(Exception):
    """Something the direct writer does not encode as xarray would: the Dataset goes through xarray."""


def _attribute(value: Any) -> Any:
    """A global or variable attribute as xarray's NetCDF3 encoding gives it to scipy."""
    if isinstance(value, str):
        return value.encode("utf-8")
    if isinstance(value, bytes):
        return value
    array = np.atleast_1d(value)
    if array.ndim != 1:
        raise _Unsupported
    kind = array.dtype.kind
    if kind == "b":
        return array.astype(np.int8)
    if array.dtype == np.int64:
        cast = array.astype(np.int32)
        if not (cast == array).all():
            raise _Unsupported
        return cast
    if array.dtype in (np.int32, np.int16, np.int8, np.float64, np.float32):
        return array
    raise _Unsupported


def _encode(dataset) -> tuple[dict[str, int], dict[str, Any], list[tuple]] | None:
    """Dimensions, global attributes and variables (name, dims, data, attrs) in the order xarray's scipy
    backend writes them; None where the Dataset holds anything else than float variables and string
    labels without encodings."""
    try:
        variables = dataset.variables
        coordinates = set(dataset.coords)
        dimension_names = set(dataset.dims)
        labels = [name for name in coordinates if name not in dimension_names]  # non-dimension coordinates
        if any(not isinstance(name, str) or " " in name for name in variables):
            return None
        # CF "coordinates": each variable (not a coordinate, not a dimension's own) names the labels
        # over a subset of its dimensions, sorted
        placed: set[str] = set()
        encoded = []
        for name, variable in variables.items():
            if variable.encoding or "coordinates" in variable.attrs or "_FillValue" in variable.attrs:
                return None
            attrs = {key: _attribute(value) for key, value in variable.attrs.items()}
            over = sorted(
                label
                for label in labels
                if name not in coordinates and name not in variable.dims
                and set(variables[label].dims) <= set(variable.dims)
            )
            if over:
                attrs["coordinates"] = _attribute(" ".join(over))
                placed.update(over)
            data = np.asarray(variable.values)
            dims = tuple(str(d) for d in variable.dims)
            if data.ndim == 0:
                return None
            if data.dtype.kind == "f":
                attrs["_FillValue"] = _attribute(data.dtype.type(np.nan))
            elif data.dtype.kind == "U":
                attrs["_Encoding"] = _attribute("utf-8")
                data = np.array([x.encode("utf-8") for x in data.ravel()], dtype=bytes).reshape(data.shape)
                width = data.dtype.itemsize
                data = data.reshape(data.shape + (1,)).view("S1")
                dims = dims + (f"string{width}",)
            else:
                return None
            encoded.append((name, dims, data, attrs))
        if set(labels) - placed:  # xarray would write a global "coordinates" attribute
            return None
        lengths: dict[str, int] = {}  # in the order of first use, as xarray creates them
        for _, names, data, _ in encoded:
            for dim, length in zip(names, data.shape):
                if lengths.setdefault(dim, length) != length:
                    return None
        attributes = {str(key): _attribute(value) for key, value in dataset.attrs.items()}
    except _Unsupported:
        return None
    return lengths, attributes, encoded


def _write(path: Path, dims: dict[str, int], attributes: dict[str, Any], variables: list[tuple]) -> None:
    from scipy.io import netcdf_file

    with netcdf_file(path, mode="w", mmap=None, version=_VERSION) as file:
        for key, value in attributes.items():
            setattr(file, key, value)
        for dim, length in dims.items():
            file.createDimension(dim, length)
        for name, names, data, attrs in variables:
            variable = file.createVariable(name, data.dtype, list(names))
            for key, value in attrs.items():
                setattr(variable, key, value)
            variable[...] = data
