"""Every figure function writes a PNG of its documented pixel size, and the same data give the same bytes."""

import struct

import numpy as np
import pytest
from matplotlib import image

from kalcal.plots import consistency, ensemble
from kalcal.plots import realization as single

WIDE = 900
ONE_ROW, TWO_ROWS, THREE_ROWS = 400, 650, 900

# (name, draw(stats, long_stats, realization, path), expected (width, height) in px); three states, two measurements
FIGURES = [
    ("state_position", lambda s, l, r, p: single.plot_state_estimate(r, 0, p), (WIDE, ONE_ROW)),
    ("state_bias", lambda s, l, r, p: single.plot_state_estimate(r, 2, p), (WIDE, ONE_ROW)),
    ("error_velocity", lambda s, l, r, p: single.plot_estimation_error(r, 1, p), (WIDE, ONE_ROW)),
    ("error_bias_magnified", lambda s, l, r, p: single.plot_estimation_error_magnified(r, 2, p), (WIDE, TWO_ROWS)),
    ("mean_error", lambda s, l, r, p: ensemble.plot_mean_error(s, p), (WIDE, THREE_ROWS)),
    ("mean_error_long", lambda s, l, r, p: ensemble.plot_mean_error(l, p, title="long"), (WIDE, THREE_ROWS)),
    ("variance_diagonal", lambda s, l, r, p: ensemble.plot_variance_diagonal(s, p), (WIDE, THREE_ROWS)),
    ("variance_offdiagonal", lambda s, l, r, p: ensemble.plot_variance_offdiagonal(s, p), (WIDE, THREE_ROWS)),
    ("orthogonality_diagonal", lambda s, l, r, p: ensemble.plot_orthogonality_diagonal(s, p), (WIDE, THREE_ROWS)),
    ("orthogonality_offdiagonal", lambda s, l, r, p: ensemble.plot_orthogonality_offdiagonal(s, p), (WIDE, THREE_ROWS)),
    ("nees", lambda s, l, r, p: consistency.plot_nees(s, p), (WIDE, TWO_ROWS)),
    ("nis", lambda s, l, r, p: consistency.plot_nis(s, p), (WIDE, ONE_ROW)),
    ("residual_correlation", lambda s, l, r, p: consistency.plot_residual_correlation(s, p), (WIDE, 800)),
    ("model_error", lambda s, l, r, p: consistency.plot_model_error(s, p), (WIDE, ONE_ROW)),
]


def png_header_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


@pytest.mark.parametrize(("name", "draw", "size"), FIGURES, ids=[f[0] for f in FIGURES])
def test_figure_writes_png_of_expected_size(plots_run, tmp_path, name, draw, size):
    stats, long_stats, data = plots_run
    path = draw(stats, long_stats, data, tmp_path / "sub" / f"{name}.png")
    assert path == tmp_path / "sub" / f"{name}.png" and path.stat().st_size > 10_000
    assert png_header_size(path) == size
    pixels = image.imread(path)
    assert pixels.shape[:2] == (size[1], size[0])
    # not a blank canvas: a figure has many distinct colours
    rgb = np.round(pixels[..., :3] * 255).astype(np.int64)
    assert np.unique(rgb[..., 0] * 65536 + rgb[..., 1] * 256 + rgb[..., 2]).size > 20


def test_figure_bytes_are_deterministic(plots_run, tmp_path):
    stats, _, data = plots_run
    first = single.plot_estimation_error(data, 0, tmp_path / "a.png").read_bytes()
    second = single.plot_estimation_error(data, 0, tmp_path / "b.png").read_bytes()
    assert first == second
    assert b"Software" not in first and b"matplotlib" not in first.lower()


def test_figures_leave_pyplot_alone(plots_run, tmp_path):
    """Figures are built without pyplot, so none piles up in its figure manager."""
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    consistency.plot_nis(plots_run[0], tmp_path / "nis.png")
    assert plt.get_fignums() == before


def test_magnified_window_is_last_two_thirds():
    times = np.arange(1, 31) * 0.2
    window = single.magnified_window(times)
    assert window[-1] and not window[0]
    assert times[window][0] >= times[0] + (times[-1] - times[0]) / 3


def test_residual_correlation_of_one_update_warns_nothing(tmp_path):
    """A batch estimator's checks hold one update: its map is one cell, drawn without matplotlib's warning
    about a zero-width extent (the spacing of the update times is undefined there)."""
    import warnings

    import xarray as xr

    moment = np.eye(2).reshape(1, 2, 1, 2)
    dataset = xr.Dataset({"residual_second_moment": (("k", "a", "j", "b"), moment)},
                         coords={"time": ("k", [3.0]), "measurement": ("a", ["x", "y"])},
                         attrs={"realizations": 400, "confidence": 0.99})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        path = consistency.plot_residual_correlation(dataset, tmp_path / "one.png")
    assert image.imread(path).shape[0] > 0
