"""``kalcal noise``: accelerometer noise from a static log, through :func:`kalcal.noise`."""

from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import escape, user_errors


def noise(
    imu: Annotated[
        Optional[Path],
        typer.Option(
            "--imu",
            help="Static accelerometer log: CSV (.csv, .csv.gz/.bz2/.xz/.zst) or Parquet (time [s], accel [m/s^2]), "
            "a ROS 1/2 bag (.bag, bag folder, .db3, .mcap; sensor_msgs/Imu) or a PX4 ULog (.ulg; sensor_combined).",
        ),
    ] = None,
    topic: Annotated[
        Optional[str],
        typer.Option("--topic", help="The bag's IMU topic (default: its only sensor_msgs/Imu topic) or the ULog's topic."),
    ] = None,
    axis: Annotated[
        Optional[str],
        typer.Option("--axis", help="x, y or z: a bag's or ULog's axis whose filter.toml is written (none without it)."),
    ] = None,
    out: Annotated[
        Path, typer.Option("--out", help="Directory for summary.json, allan.csv, allan.png, filter.toml, imu.yaml.")
    ] = Path(
        "kalcal-noise"
    ),
    imu_columns: Annotated[
        Optional[str], typer.Option("--imu-columns", help="Map roles to columns, e.g. time=t,accel=ax.")
    ] = None,
    kalibr: Annotated[
        bool,
        typer.Option(
            "--kalibr/--no-kalibr",
            help="Write imu.yaml, the noise as Kalibr's densities (m/s^2/sqrt(Hz), m/s^3/sqrt(Hz)); null where not identified.",
        ),
    ] = True,
    strict: Annotated[
        bool, typer.Option("--strict", help="Refuse (exit status 2, nothing written) a log that does not look static.")
    ] = False,
) -> None:
    """Identify accelerometer noise from a static log: Allan deviation, N, B, K and the [filter] settings.

    N (velocity random walk, m/s/sqrt(s)) from the -1/2 slope, B (bias instability, m/s^2) from the flat
    minimum, K (rate random walk, m/s^2/sqrt(s)) from the +1/2 slope; filter.toml holds the rate-free
    accel_noise_density = N and, where K is seen, bias_walk_density = K, for calibrate --config, which
    converts them at each log's own rate (the per-sample values at this log's rate are in comments).
    """
    from rich import box

    from kalcal.api.noise import noise as run_noise
    from kalcal.errors import KalcalError

    with user_errors():
        if imu is None:
            raise KalcalError("--imu: required (a static accelerometer log: time [s], accel [m/s^2])")
        result = run_noise(imu, imu_columns=imu_columns, strict=strict, out=out, kalibr=kalibr, topic=topic, axis=axis)
    summary = {**result.raw_summary, "files": result.paths}
    blocks = summary["axes"] if "axes" in summary else {None: summary}
    table = _common._table(
        f"kalcal noise: {summary['samples']:,} samples at {summary['rate']['value']:.6g} Hz"
        + (f", {len(blocks)} axes" if len(blocks) > 1 else ""),
        f"{summary['duration']['value']:.6g} s",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    if len(blocks) > 1:
        table.add_column("axis", no_wrap=True)
    table.add_column("quantity", no_wrap=True)
    table.add_column("value", justify="right", no_wrap=True)
    table.add_column(f"{100 * summary['confidence']:g}% interval", justify="right", no_wrap=True)
    table.add_column("unit", no_wrap=True)
    regions = []
    for axis_name, block in blocks.items():
        lead = [] if axis_name is None else [axis_name]
        where = "" if axis_name is None else f"{axis_name}: "
        for name in ("accel_noise_std", "velocity_random_walk", "bias_instability", "rate_random_walk", "bias_walk_std"):
            item = block[name]
            if item["identified"]:
                table.add_row(*lead, name, f"{item['value']:.4g}", f"{item['ci_low']:.3g}-{item['ci_high']:.3g}", item["unit"])
                if name in ("velocity_random_walk", "bias_instability", "rate_random_walk"):
                    first, last = item["tau_range"]
                    regions.append(f"{where}{name} at tau = {first:.3g}" + ("" if first == last else f"-{last:.3g}") + " s")
            else:
                table.add_row(*lead, name, "not seen", f"< {item['upper_bound']:.3g}", item["unit"])
    _common.console.print(table)
    if regions:
        _common.console.print("read off the curve: " + "; ".join(regions), markup=False)
    for note in summary["notes"]:
        _common.console.print(f"note: {escape(note)}")
    _common._print_warnings(summary)
    files = summary["files"]
    _common._note_nonfinite(files["summary"])
    written = [files[key] for key in ("summary", "allan", "plot", "filter", "kalibr") if key in files]
    _common.print_wrote(Path(out), written)
