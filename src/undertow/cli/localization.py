"""Localization commands: localize, calibrate, evaluate trajectory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import UndertowError
from ._app import (
    ConfigOption,
    InPiecesOption,
    OverwriteOption,
    PieceSOption,
    QuietOption,
    SoundSpeedOption,
    TimeOption,
    TopicsOption,
    app,
    console,
    err,
    evaluate_app,
    parse_triple,
    pieces_option,
    print_json,
    print_warnings,
    progress_bar,
    settings_with_time,
    user_errors,
)

EstimatorOption = Annotated[
    str,
    typer.Option(
        help="ukf (the paper's filter) | factor-graph (GTSAM batch smoother) | isam2 (GTSAM "
        "incremental, online) | inekf (invariant EKF); the peers read the same sensors and "
        "noise, plus the accelerometer; needs undertow[peers]."
    ),
]


@app.command()
@user_errors
def localize(
    log_path: Annotated[
        Path, typer.Argument(metavar="LOG", help="Bag, A50 JSON log, MAVLink .tlog or .BIN.")
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
        bool, typer.Option(help="Outside the profile: the nearest condition as is, not scaled.")
    ] = False,
    calibration: Annotated[
        Path | None, typer.Option(help="Calibration YAML from `undertow calibrate`.")
    ] = None,
    initial_position: Annotated[
        str | None,
        typer.Option(help="Start position 'x,y,z' in m (default: ground truth if the log has it)."),
    ] = None,
    smooth: Annotated[bool, typer.Option(help="Unscented RTS smoothing (offline).")] = False,
    in_pieces: InPiecesOption = None,
    piece_s: PieceSOption = None,
    estimator: EstimatorOption = "ukf",
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
    time: TimeOption = None,
    sound_speed: SoundSpeedOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Localize a log with the paper's 18-state UKF; writes trajectory.tum/.npz and config.yaml.

    Example: `undertow localize runs/a10/log --variant proposed --wave wave-a0.10-f1.00
    --calibration calm_cal.yaml --out runs/a10/proposed`"""
    from ..commands.localization import gate_option, localize_file

    condition = _wave_option(wave, wave_amplitude, wave_frequency)
    start = parse_triple(initial_position, "--initial-position")
    options = {"variant": variant, "output_rate_hz": output_rate, "initial_position": start}
    with progress_bar(quiet) as progress:
        progress.add_task(_task_label(variant, estimator), total=None)
        result = localize_file(
            log_path, settings_with_time(config, time, sound_speed), topics=topics, out_dir=out_dir,
            overwrite=overwrite, profile=profile, calibration=calibration,
            extrapolate=extrapolate, smooth=smooth, wave=condition, estimator=estimator,
            **pieces_option(in_pieces, piece_s), **gate_option(gate),
            **{name: value for name, value in options.items() if value is not None},
        )  # fmt: skip
    print_warnings(result.warnings)
    if not quiet:
        _print_localized(result, out_dir, wave)


def _task_label(variant: str | None, estimator: str) -> str:
    """The progress line: 'localizing (variant, estimator)' (the default ukf left out)."""
    what = ", ".join(v for v in (variant, estimator) if v and v != "ukf")
    return f"localizing{f' ({what})' if what else ''}"


def _print_localized(result, out_dir: Path, wave: str | None) -> None:
    """What `localize` says once done: the wave condition and where it came from, the files
    written, the one-line consistency summary."""
    err.print(f"wave condition: {result.wave} ({_wave_source(result, wave)})",
              highlight=False, soft_wrap=True)  # fmt: skip
    err.print(f"wrote {out_dir}/trajectory.tum, trajectory.npz, config.yaml")
    if result.consistency is not None:
        err.print(
            f"consistency: {result.consistency.summary()} (`undertow evaluate trajectory "
            f"{out_dir}` for the report)",
            highlight=False,
            soft_wrap=True,
        )


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
    from ..estimation.wave_schedule import WAVE_LIVE

    if result.wave_source == WAVE_LIVE:  # a live --wave auto recording: its own decisions
        how = f"{WAVE_LIVE}, replayed as the live filter took them; --wave NAME overrides"
    elif by_name is not None and by_name.strip().lower() == "auto":
        how = "--wave auto: estimated over time from the log; config.yaml has wave_track"
    elif result.wave_source == WAVE_GIVEN:
        how = "--wave" if by_name is not None else "--wave-amplitude/--wave-frequency"
    elif result.wave_source == WAVE_DEFAULT:
        how = "default: none given, none recorded in the log; set it with --wave"
    else:
        how = f"from {result.wave_source}; --wave overrides"
    if not result.wave_noise_added:
        how += f"; the {result.variant} variant adds no wave noise"
    else:
        config = result.trajectory.metadata.get("config") or {}
        if result.wave != "calm" and config.get("pressure_wave_noise"):
            heading = config.get("wave_heading_deg")
            how += "; the barometer's swell is tracked by two wave-model states " + (
                f"at the encounter frequency of waves toward {heading:g} deg (wave_heading_deg)"
                if heading is not None
                else "over the Doppler range (the waves' direction unknown: wave_heading_deg)"
            )
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
    sound_speed: SoundSpeedOption = None,
    quiet: QuietOption = False,
) -> None:
    """Estimate the DR drift mu_b, the IMU gyro bias and the DVL scale factor from a run with
    ground truth, for later runs (`undertow localize --calibration`); with the water's sound
    speed given, the scale factor is what it leaves.

    Example: `undertow calibrate runs/calm/log runs/calm/ground_truth.tum --out calm_cal.yaml`
    """
    from ..commands.localization import calibrate_file

    with progress_bar(quiet) as progress:
        progress.add_task("calibrating", total=None)
        settings = settings_with_time(config, None, sound_speed)
        result = calibrate_file(log_path, ground_truth, settings, topics=topics, out=out)
    print_warnings(result.warnings)
    print_json(result.calibration.to_dict())
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
    reference_path: Annotated[
        Path | None,
        typer.Argument(
            metavar="[REFERENCE]",
            help="Ground-truth TUM file (e.g. 2000 Hz), or with --reference the log to take the "
            "reference from (bag, mcap folder, .BIN, .tlog); none: the consistency report only.",
        ),
    ] = None,
    reference: Annotated[
        str | None,
        typer.Option(
            help="gps | dvl-dr | autopilot: REFERENCE is a log, compared with its GPS fixes, "
            "the DVL's own dead reckoning or the autopilot's EKF (drift in % of distance)."
        ),
    ] = None,
    align: Annotated[
        str | None,
        typer.Option(
            help="Ground truth: none (default) | origin (first poses made equal). A log's "
            "reference: start (default: translated to agree at the first common time) | yaw "
            "(and rotated by the least-squares yaw over the first 10 % of the path) | none."
        ),
    ] = None,
    checkpoints: Annotated[
        int,
        typer.Option(help="Checkpoints of a continuous reference, evenly spaced in distance."),
    ] = 10,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Per-axis RMSE (x, y, z, roll, pitch, yaw, vx, vy, vz; the paper's Table II) and NEES
    against ground truth, or the drift against a reference from the log (no ground truth); then
    the filter's consistency report (NIS per sensor, whiteness) recorded by `undertow localize`.

    Examples: `undertow evaluate trajectory runs/a10/proposed runs/a10/ground_truth.tum --json`;
    `undertow evaluate trajectory out/ mylog.mcap --reference dvl-dr`
    """
    from ..commands.localization import evaluate_trajectory_file
    from ..errors import DataError

    evaluation = evaluate_trajectory_file(
        estimate, reference_path, align, reference=reference, settings=config, topics=topics,
        checkpoints=checkpoints,
    )  # fmt: skip
    print_warnings(evaluation.warnings)
    if reference_path is None and evaluation.consistency is None:
        raise DataError(
            f"{estimate}: the trajectory carries no consistency report (written before undertow "
            "recorded one, or not by `undertow localize`); give a REFERENCE to compare it with"
        )
    if as_json:
        print_json(evaluation.to_dict())
        return
    if evaluation.errors is not None:
        _print_errors(evaluation.errors, estimate)
    if evaluation.drift is not None:
        _print_drift(evaluation.drift, estimate)
    if evaluation.consistency is not None:
        _print_consistency(evaluation.consistency)
    elif reference_path is not None:
        console.print("consistency: none recorded with this trajectory")


def _print_errors(result, estimate: Path) -> None:
    """The RMSE table and the NEES line."""
    from rich.table import Table

    table = Table(title=f"RMSE of {estimate} (align {result.align})")
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


def _number(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _print_drift(drift, estimate: Path) -> None:
    """The drift table, then the alignment, the checkpoint rule and the growth."""
    from rich import box
    from rich.table import Table

    table = Table(
        title=f"Drift of {estimate} against {drift.reference} ({drift.source})",
        box=box.SIMPLE_HEAD,
        show_edge=False,
        pad_edge=False,
    )
    vertical = drift.reference != "gps"
    columns = ["time s", "distance m", "drift m", "drift %", "along m", "cross m"]
    for name in columns + (["vertical m"] if vertical else []):
        table.add_column(name, justify="right")
    for c in drift.checkpoints:
        row = [f"{c.t_s - drift.start_t_s:.1f}", f"{c.distance_m:.1f}", f"{c.drift_m:.2f}"]
        row += [_number(v) for v in (c.drift_percent, c.along_track_m, c.cross_track_m)]
        table.add_row(*row, *([_number(c.vertical_m)] if vertical else []))
    console.print(table)
    console.print(f"alignment: {drift.alignment_text()}", highlight=False, soft_wrap=True)
    console.print(
        f"checkpoints: {drift.checkpoint_rule}; time from t0 = {drift.start_t_s:.3f} s (the first "
        "common time)",
        highlight=False,
        soft_wrap=True,
    )
    final = (
        f"final drift {drift.final_drift_m:.2f} m"
        + (f" = {drift.final_drift_percent:.2f} %" if drift.final_drift_percent is not None else "")
        + f" of {drift.distance_m:.1f} m travelled"
    )
    growth = (
        "growth: none (no distance travelled)"
        if drift.growth_percent is None
        else f"growth: {drift.growth_percent:.2f} % of distance (along "
        f"{_number(drift.along_growth_percent)} %, cross {_number(drift.cross_growth_percent)} %)"
    )
    console.print(f"{final}; {growth}", highlight=False, soft_wrap=True)


def _print_consistency(report) -> None:
    """The consistency table: per sensor, the mean NIS over its expected value against its
    band, the share outside, the lag-1 autocorrelation against its band, and the verdict; then
    how to read them."""
    from rich import box
    from rich.table import Table

    from ..estimation.consistency import LABELS, MEANING

    table = Table(title="Consistency of the filter's innovations", box=box.SIMPLE_HEAD,
                  show_edge=False, pad_edge=False, collapse_padding=True)  # fmt: skip
    for name in ("sensor", "n", "NIS/dof", "95 % band", "outside", "lag-1 (band)", "verdict"):
        table.add_column(name, justify="left" if name in ("sensor", "verdict") else "right")
    for s in report.sensors:
        if not s.count:
            table.add_row(s.sensor, "0", "-", "-", "-", "-", s.verdict)
            continue
        rho = "-"
        if s.autocorrelation_lag1 is not None:
            rho = f"{s.autocorrelation_lag1:+.2f} ({s.autocorrelation_band:.2f})"
            rho += "" if s.white else "!"
        table.add_row(
            s.sensor, str(s.count), f"{s.nis_mean:.3g}/{s.dof}",
            f"{s.nis_band_low:.3g}-{s.nis_band_high:.3g}",
            f"{100 * s.share_outside:.0f} %" + ("" if s.share_as_expected else "!"), rho,
            LABELS.get(s.verdict, s.verdict),
        )  # fmt: skip
    console.print(table)
    lines = [
        "NIS/dof: mean NIS over its expected value; ok inside the 95 % band (or within 10 %); "
        "outside: share of NIS beyond the per-sample 95 % interval, expected 5 %; lag-1: "
        "autocorrelation of consecutive innovations, expected within +-(band); ! marks a "
        "departure"
    ]
    verdicts = dict.fromkeys(s.verdict for s in report.evaluated)
    lines += [f"{LABELS.get(v, v)} ({v}): {MEANING[v]}" for v in verdicts]
    for line in lines:
        console.print(line, highlight=False, soft_wrap=True)
