"""Ensemble statistics to and from NetCDF (``stats.nc``): the Dataset of :mod:`kalcal.verification.dataset`.

Dimensions: ``time`` (K update times, s), ``state``/``state2`` (d), ``measurement``/``measurement2`` (p),
and ``time2`` (a second copy of ``time`` for the residual correlation over pairs of updates, present
only when the run kept the pairs). Written as
NetCDF3 through scipy, so no extra library is needed to read it: ``xarray.open_dataset("stats.nc")``.
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from kalcal.errors import DataError


def write_statistics(path: str | Path, dataset: xr.Dataset) -> Path:
    """Write the Dataset as NetCDF."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    dataset.to_netcdf(path, engine="scipy")
    return path


def read_statistics(path: str | Path) -> xr.Dataset:
    """Read a ``stats.nc`` written by :func:`write_statistics` (fully loaded, file closed)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such statistics file")
    try:
        with xr.open_dataset(path, engine="scipy") as dataset:
            return dataset.load()
    except (OSError, ValueError, TypeError) as exc:
        raise DataError(f"{path}: not a kalcal statistics file ({exc})") from None
