"""Localization commands: localize, calibrate, evaluate trajectory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._util.atomic import check_output_folder
from ..errors import UndertowError
from ._app import (
    ConfigOption,
    OverwriteOption,
    TopicsOption,
    _load_log,
    _print_json,
    _progress,
    _read_ground_truth,
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
    log_path: Annotated[Path, typer.Argument(metavar="LOG", help="Bag or A50 JSON log.")],
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")],
    variant: Annotated[
        str | None,
        typer.Option(help="baseline | be (bias estimation) | an (added noise) | proposed"),
    ] = None,
    profile: Annotated[
        Path | None, typer.Option(help="Wave noise profile YAML (default: the paper's Table I).")
    ] = None,
    wave: Annotated[
        str | None,
        typer.Option(
            help="Wave condition by name, e.g. calm or wave-a0.10-f1.00 (default: the one the "
            "log records, e.g. in the bag's sidecar undertow.yaml, else calm)."
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
        float | None,
        typer.Option(
            help="Mahalanobis gate: drop a measurement whose NIS exceeds the chi-square quantile "
            "of this probability, e.g. 0.999 (default: off)."
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
    from ..estimation.localizer import wave_condition
    from ..estimation.noise import parse_wave
    from ..estimation.run import localize as run_localize
    from ..io.results import save_trajectory
    from ..settings import Settings

    numbers = {"--wave-amplitude": wave_amplitude, "--wave-frequency": wave_frequency}
    by_number = [name for name, value in numbers.items() if value is not None]
    if wave is not None and by_number:
        raise UndertowError(
            f"--wave and {' / '.join(by_number)} conflict: give the condition by name (--wave) "
            "or by --wave-amplitude and --wave-frequency, not both"
        )
    if len(by_number) == 1:
        raise UndertowError("give both --wave-amplitude and --wave-frequency (or --wave NAME)")
    condition = (wave_amplitude, wave_frequency) if wave_amplitude is not None else wave
    settings = Settings.from_yaml(config)
    params = settings.localizer_params()
    variant = variant or params.pop("variant", "proposed")
    params.pop("variant", None)
    if output_rate is not None:
        params["output_rate_hz"] = output_rate
    if gate is not None:
        params["gate_probability"] = gate
    if smooth and params.get("output_rate_hz") is not None:
        given = "--output-rate" if output_rate is not None else f"output_rate_hz in {config}"
        raise UndertowError(
            f"--smooth needs the filter output at every measurement: drop {given} "
            f"({params['output_rate_hz']} Hz) or --smooth"
        )
    check_output_folder(out_dir, overwrite, inputs=[log_path, profile, calibration, config, topics])
    with _progress(quiet) as progress:
        progress.add_task(f"localizing ({variant})", total=None)
        log = _load_log(log_path, topics, settings)
        used, source = wave_condition(condition, log)
        if not quiet:
            how = {
                "given": "--wave" if wave is not None else "--wave-amplitude/--wave-frequency",
                "default": "default: none given, none recorded in the log; set it with --wave",
            }.get(source, f"from {source}; --wave overrides")
            unused = (
                f"; the {variant} variant adds no wave noise"
                if variant in ("baseline", "be")
                else ""
            )
            err.print(
                f"wave condition: {parse_wave(used)[0]} ({how}{unused})",
                highlight=False,
                soft_wrap=True,
            )
        trajectory = run_localize(
            log,
            variant=variant,
            profile=profile,
            wave=condition,
            calibration=calibration,
            initial_position=_triple(initial_position, "--initial-position") or "auto",
            extrapolate=extrapolate,
            smooth=smooth,
            **params,
        )
        save_trajectory(trajectory, out_dir, overwrite)
    if not quiet:
        err.print(f"wrote {out_dir}/trajectory.tum, trajectory.npz, config.yaml")


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
    from ..estimation.calibration import calibrate as run_calibration
    from ..settings import Settings

    with _progress(quiet) as progress:
        progress.add_task("calibrating", total=None)
        log = _load_log(log_path, topics, Settings.from_yaml(config))
        if ground_truth is not None:
            log = log.replace(ground_truth=_read_ground_truth(ground_truth))
        result = run_calibration(log)
        result.save_yaml(out)
    _print_json(result.to_dict())
    if not quiet:
        err.print(
            f"wrote {out} (estimated: {', '.join(result.estimated)})",
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

    from ..evaluation.trajectory import trajectory_rmse
    from ..trajectory import Trajectory

    result = trajectory_rmse(Trajectory.load_npz(estimate), _read_ground_truth(ground_truth), align)
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
