"""Ensemble statistics to and from NetCDF (``stats.nc``): the Dataset of :mod:`kalcal.stats.dataset`.

Dimensions: ``time`` (K update times, s), ``state``/``state2`` (d), ``measurement``/``measurement2`` (p),
and ``time2`` (a second copy of ``time``, always there; ``residual_second_moment``, the
residual correlation over pairs of updates, runs over it where the run kept the pairs). Written as
NetCDF3 by xarray's scipy engine, so no extra library is needed to read it: ``xarray.open_dataset("stats.nc")``.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import TYPE_CHECKING

from kalcal.errors import DataError

if TYPE_CHECKING:
    import xarray as xr

#: what scipy's NetCDF reader (and xarray's decoding over it) raises on a file cut short or corrupt: in
#: the header an IndexError or a struct.error, a KeyError for a bad type code, a MemoryError or
#: OverflowError for a huge count, a ValueError for short data, a LookupError for a bad encoding, an
#: AttributeError or TypeError for an attribute of the wrong type (the nets hold the reading alone)
_UNREADABLE = (OSError, ValueError, TypeError, LookupError, MemoryError, OverflowError, AttributeError, struct.error,
               EOFError)  # fmt: skip


def write_statistics(path: str | Path, dataset: xr.Dataset) -> Path:
    """Write the Dataset as NetCDF3 (``dataset.to_netcdf(path, engine="scipy")``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    dataset.to_netcdf(path, engine="scipy")
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
