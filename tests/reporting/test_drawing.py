"""The report's figures drawn in parallel processes are the same files as drawn one by one."""

import multiprocessing

import pytest

from kalcal.errors import DataError
from kalcal.jobs.report import render_report
from kalcal.reporting import drawing


def test_parallel_figures_are_the_serial_bytes(report_run, copy_run, monkeypatch):
    """report_run drew its figures with the default workers; a copy drawn in this process matches."""
    saved, _ = report_run
    serial = copy_run()
    monkeypatch.setattr(drawing, "drawing_workers", lambda figures: 1)
    render_report(serial, realization=4321)
    names = sorted(p.name for p in (saved / "figures").glob("*.png"))
    assert len(names) >= 15
    assert names == sorted(p.name for p in (serial / "figures").glob("*.png"))
    for name in names:
        assert (saved / "figures" / name).read_bytes() == (serial / "figures" / name).read_bytes(), name


def _write(path):
    path.write_text(path.stem)
    return path


def _fail(path):
    raise DataError(f"{path.name}: cannot be drawn")


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork on this platform")
def test_results_in_order_progress_counted_and_errors_raised(tmp_path):
    paths = [tmp_path / f"f{i}.png" for i in range(5)]
    seen = []
    written = drawing.draw_all([_write] * 5, paths, workers=2, progress=lambda done, total: seen.append((done, total)))
    assert written == paths
    assert [p.read_text() for p in paths] == [f"f{i}" for i in range(5)]
    assert seen == [(i, 5) for i in range(1, 6)]
    with pytest.raises(DataError, match="f1.png: cannot be drawn"):
        drawing.draw_all([_write, _fail, _write], paths[:3], workers=2)


def test_one_worker_per_cpu_at_most_one_per_figure():
    assert drawing.drawing_workers(1) == 1
    assert 1 <= drawing.drawing_workers(100) <= multiprocessing.cpu_count()
