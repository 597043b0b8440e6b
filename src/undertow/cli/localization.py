"""Localization commands: localize, calibrate, evaluate trajectory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import UndertowError
from ._app import (
    ConfigOption,
    OverwriteOption,
    TopicsOption,
    _print_json,
    _print_warnings,
    _progress,
    _triple,
    app,
    console,
    err,
    evaluate_app,
    user_errors,
)

QuietOption = Annotated[
    bool, typer.Option("--quiet", "-q", help="No progress or summary on stderr.")
]


@app.command()
@user_errors
def localize(
    log_path: Annotated[
        Path, typer.Argument(metavar="LOG", help="Bag, A50 JSON log or MAVLink .tlog.")
    ],
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")],
    variant: Annotated[
        str | None,
        typer.Option(
            help="baseline | be (bias estimation) | an (added noise) | proposed | adaptive-r "
            "(innovation-adaptive R, a peer baseline)"
        ),
    ] = None,
    profile: Annotated[
        Path | None, typer.Option(help="Wave noise profile YAML (default: the paper's Table I).")
    ] = None,
    wave: Annotated[
        str | None,
        typer.Option(
            help="Wave condition: auto (estimated over time from the log's own barometer, DVL "
            "and orientation; the noise follows it), or a name, e.g. calm or wave-a0.10-f1.00 "
            "(default: the one the log records, e.g. in the bag's sidecar undertow.yaml, else "
            "calm)."
        ),
    ] = None,
    wave_amplitude: Annotated[float | None, typer.Option(help="Wave amplitude, m.")] = None,
    wave_frequency: Annotated[float | None, typer.Option(help="Wave frequency, Hz.")] = None,
    extrapolate: Annotated[
        bool, typer.Option(help="Allow wave conditions outside the characterized ones.")
    ] = False,
    calibration: Annotated[
        Path | None, typer.Option(help="Calibration YAML from `undertow calibrate`.")
    ] = None,
    initial_position: Annotated[
        str | None,
        typer.Option(help="Start position 'x,y,z' in m (default: ground truth if the log has it)."),
    ] = None,
    smooth: Annotated[bool, typer.Option(help="Unscented RTS smoothing (offline).")] = False,
    gate: Annotated[
        str | None,
        typer.Option(
            help="Mahalanobis gate: a probability, e.g. 0.999, drops a measurement whose NIS "
            "exceeds that chi-square quantile; 'off' disables gating (default: a 20-sigma gate "
            "on the DVL, DR and barometer)."
        ),
    ] = None,
    output_rate: Annotated[
        float | None, typer.Option(help="Output rate, Hz (default: every measurement).")
    ] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Localize a log with the paper's 18-state UKF; writes trajectory.tum/.npz and config.yaml.

    Example: `undertow localize runs/a10/log --variant proposed --wave wave-a0.10-f1.00
    --calibration calm_cal.yaml --out runs/a10/proposed`
    """
    from ..jobs.localize import gate_option, localize_file

    condition = _wave_option(wave, wave_amplitude, wave_frequency)
    options = {
        "variant": variant,
        "output_rate_hz": output_rate,
        "initial_position": _triple(initial_position, "--initial-position"),
    }
    with _progress(quiet) as progress:
        progress.add_task(f"localizing{f' ({variant})' if variant else ''}", total=None)
        result = localize_file(
            log_path, config, topics=topics, out_dir=out_dir, overwrite=overwrite,
            profile=profile, calibration=calibration, extrapolate=extrapolate, smooth=smooth,
            wave=condition,
            **{name: value for name, value in options.items() if value is not None},
            **gate_option(gate),
        )  # fmt: skip
    _print_warnings(result.warnings)
    if not quiet:
        err.print(f"wave condition: {result.wave} ({_wave_source(result, wave)})",
                  highlight=False, soft_wrap=True)  # fmt: skip
        err.print(f"wrote {out_dir}/trajectory.tum, trajectory.npz, config.yaml")


def _wave_option(name: str | None, amplitude: float | None, frequency: float | None):
    """The wave condition given by name or by both numbers (None: not given)."""
    numbers = {"--wave-amplitude": amplitude, "--wave-frequency": frequency}
    by_number = [option for option, value in numbers.items() if value is not None]
    if name is not None and by_number:
        raise UndertowError(
            f"--wave and {' / '.join(by_number)} conflict: give the condition by name (--wave) "
            "or by --wave-amplitude and --wave-frequency, not both"
        )
    if len(by_number) == 1:
        raise UndertowError("give both --wave-amplitude and --wave-frequency (or --wave NAME)")
    return (amplitude, frequency) if by_number else name


def _wave_source(result, by_name: str | None) -> str:
    """Where the wave condition of ``result`` came from, and the option that sets it."""
    from ..estimation.localizer import WAVE_DEFAULT, WAVE_GIVEN

    if by_name is not None and by_name.strip().lower() == "auto":
        how = "--wave auto: estimated over time from the log; config.yaml has wave_track"
    elif result.wave_source == WAVE_GIVEN:
        how = "--wave" if by_name is not None else "--wave-amplitude/--wave-frequency"
    elif result.wave_source == WAVE_DEFAULT:
        how = "default: none given, none recorded in the log; set it with --wave"
    else:
        how = f"from {result.wave_source}; --wave overrides"
    if not result.wave_noise_added:
        how += f"; the {result.variant} variant adds no wave noise"
    return how


@app.command()
@user_errors
def calibrate(
    log_path: Annotated[Path, typer.Argument(metavar="LOG", help="A run with ground truth.")],
    ground_truth: Annotated[
        Path | None,
        typer.Argument(help="Ground-truth TUM file (default: the log's ground_truth stream)."),
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="Calibration YAML to write.")] = Path(
        "calibration.yaml"
    ),
    config: ConfigOption = None,
    topics: TopicsOption = None,
    quiet: QuietOption = False,
) -> None:
    """Estimate the DR drift mu_b, the IMU gyro bias and the DVL scale factor from a run with
    ground truth, for later runs (`undertow localize --calibration`).

    Example: `undertow calibrate runs/calm/log runs/calm/ground_truth.tum --out calm_cal.yaml`
    """
    from ..jobs.localize import calibrate_file

    with _progress(quiet) as progress:
        progress.add_task("calibrating", total=None)
        result = calibrate_file(log_path, ground_truth, config, topics=topics, out=out)
    _print_warnings(result.warnings)
    _print_json(result.calibration.to_dict())
    if not quiet:
        err.print(
            f"wrote {out} (estimated: {', '.join(result.calibration.estimated)})",
            highlight=False,
            soft_wrap=True,
        )


@evaluate_app.command("trajectory")
@user_errors
def evaluate_trajectory(
    estimate: Annotated[Path, typer.Argument(help="Localization folder or trajectory.npz.")],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth TUM file (e.g. 2000 Hz).")],
    align: Annotated[str, typer.Option(help="none | origin (first poses made equal).")] = "none",
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Per-axis RMSE (x, y, z, roll, pitch, yaw, vx, vy, vz; the paper's Table II) and NEES.

    Example: `undertow evaluate trajectory runs/a10/proposed runs/a10/ground_truth.tum --json`
    """
    from rich.table import Table

    from ..jobs.localize import evaluate_trajectory_file

    evaluation = evaluate_trajectory_file(estimate, ground_truth, align)
    _print_warnings(evaluation.warnings)
    result = evaluation.errors
    if as_json:
        _print_json(result.to_dict())
        return
    table = Table(title=f"RMSE of {estimate} (align {align})")
    table.add_column("axis")
    table.add_column("RMSE", justify="right")
    for key, value in result.rmse.items():
        table.add_row(key, f"{value:.4f}")
    console.print(table)
    console.print(
        f"samples: {result.samples} used, {result.dropped_outside_ground_truth} outside the "
        "ground truth (dropped)"
    )
    if result.nees_samples == 0:
        console.print(f"NEES: none (no sample of {result.samples} has a usable covariance)")
        return
    console.print(
        f"NEES (pose, 6 dof): mean {result.nees_mean:.2f}, "
        f"{100 * result.nees_fraction_in_95:.0f} % inside the 95 % bound; {result.samples} samples"
        + (
            f" ({result.nees_samples} with a usable covariance)"
            if result.nees_samples != result.samples
            else ""
        )
    )
