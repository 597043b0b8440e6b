"""The `undertow` command line: one typer app, each command a thin call of a library function.

Known user errors (UndertowError) become one line on stderr and exit code 1; anything else is
a bug and keeps its traceback.
"""

from __future__ import annotations

import functools
import json
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from .errors import UndertowError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode="markdown",
    help=(
        "undertow: uncertainty-aware acoustic localization and seafloor mapping for underwater "
        "robots in waves.\n\n"
        "Examples:\n\n"
        "    undertow simulate wave-a0.10-f1.00 --out runs/a10f100 --seed 1\n\n"
        "    undertow info runs/a10f100/log\n\n"
        "    undertow info recording.bag --json\n\n"
    ),
)
evaluate_app = typer.Typer(no_args_is_help=True, help="Evaluate results against ground truth.")
app.add_typer(evaluate_app, name="evaluate")

console = Console()
err = Console(stderr=True)


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    err.print(f"[yellow]warning:[/] {message}", highlight=False, soft_wrap=True)


@app.callback()
def _setup() -> None:
    """Library warnings (bad rows dropped, units fixed) become one line each on stderr."""
    warnings.showwarning = _one_line_warning


def user_errors(fn):
    """Turn UndertowError into one clear line and exit code 1."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except UndertowError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(1) from None

    return wrapper


def _progress(quiet: bool):
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=err,
        disable=quiet,
        transient=True,
    )


def _print_json(data) -> None:
    sys.stdout.write(json.dumps(data, indent=2, default=float) + "\n")


@app.command()
@user_errors
def info(
    path: Annotated[Path, typer.Argument(help="ROS 1 bag, ROS 2 bag directory, or A50 JSON log.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    topics: Annotated[
        Path | None, typer.Option(help="YAML topic map overriding the BlueROV2 defaults.")
    ] = None,
) -> None:
    """Streams found, message counts, rates, time span and invalid data, in measurement terms.

    Example: `undertow info runs/calm/log --json`
    """
    from .io import read_log
    from .io.info import summarize
    from .io.topics import TopicMap

    topic_map = TopicMap.from_yaml(topics) if topics else None
    summary = summarize(read_log(path, topics=topic_map))
    if as_json:
        _print_json(summary.to_dict())
    else:
        console.print(summary.to_rich_table())


@app.command()
@user_errors
def simulate(
    scenario: Annotated[
        str | None, typer.Argument(help="Built-in scenario name or a scenario YAML file.")
    ] = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="Output directory.")] = None,
    seed: Annotated[int, typer.Option(help="Random seed (runs are deterministic per seed).")] = 0,
    list_: Annotated[bool, typer.Option("--list", help="List the built-in scenarios.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output directory.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Simulate a wave-tank run: ROS 2 bag, ground truth (TUM, 2000 Hz), floor scan (PLY).

    Example: `undertow simulate wave-a0.10-f0.75 --out runs/a10f075 --seed 3`
    """
    from .sim import list_scenarios, load_scenario, write_simulation
    from .sim import simulate as run_simulation

    if list_:
        for name in list_scenarios():
            console.print(f"[bold]{name}[/]  {load_scenario(name).description}", highlight=False)
        return
    if scenario is None or out_dir is None:
        raise UndertowError("simulate needs a SCENARIO and --out DIR (or --list)")
    spec = load_scenario(scenario)
    with _progress(quiet) as progress:
        progress.add_task(f"simulating {spec.name} (seed {seed})", total=None)
        result = run_simulation(spec, seed=seed)
        write_simulation(result, out_dir, overwrite=overwrite)
    if not quiet:
        err.print(f"wrote {out_dir}/log, ground_truth.tum, ground_truth.ply, scenario.yaml")


def _load_log(path: Path, topics: Path | None, settings=None):
    """Read a log; topic names from --topics, else the settings file's, else the defaults."""
    from .io import read_log
    from .io.topics import TopicMap

    topic_map = TopicMap.from_yaml(topics) if topics else settings.topics if settings else None
    log = read_log(path, topics=topic_map)
    return settings.apply_mounting(log) if settings else log


def _triple(text: str | None, name: str):
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise UndertowError(f"{name}: expected three comma-separated numbers, got {text!r}")
    return values


TopicsOption = Annotated[
    Path | None, typer.Option(help="YAML topic map overriding the BlueROV2 defaults.")
]
ConfigOption = Annotated[
    Path | None,
    typer.Option(help="Settings YAML with topics / localizer / mapping sections (see README)."),
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
        str | None, typer.Option(help="Wave condition by name, e.g. calm or wave-a0.10-f1.00.")
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
    output_rate: Annotated[
        float | None, typer.Option(help="Output rate, Hz (default: every measurement).")
    ] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Localize a log with the paper's 18-state UKF; writes trajectory.tum/.npz and config.yaml.

    Example: `undertow localize runs/a10/log --variant proposed --wave wave-a0.10-f1.00
    --calibration calm_cal.yaml --out runs/a10/proposed`
    """
    from .estimation.run import localize as run_localize
    from .estimation.run import save_trajectory

    if (wave_amplitude is None) != (wave_frequency is None):
        raise UndertowError("give both --wave-amplitude and --wave-frequency (or --wave NAME)")
    condition = (wave_amplitude, wave_frequency) if wave_amplitude is not None else wave
    from .config import Settings

    settings = Settings.from_yaml(config)
    params = settings.localizer_params()
    variant = variant or params.pop("variant", "proposed")
    params.pop("variant", None)
    if output_rate is not None:
        params["output_rate_hz"] = output_rate
    with _progress(quiet) as progress:
        progress.add_task(f"localizing ({variant})", total=None)
        log = _load_log(log_path, topics, settings)
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
        save_trajectory(trajectory, out_dir)
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
) -> None:
    """Estimate the DR drift mu_b, the IMU gyro bias and the DVL scale factor from a run with
    ground truth, for later runs (`undertow localize --calibration`).

    Example: `undertow calibrate runs/calm/log runs/calm/ground_truth.tum --out calm_cal.yaml`
    """
    from .config import Settings
    from .estimation.calibration import calibrate as run_calibration

    log = _load_log(log_path, topics, Settings.from_yaml(config))
    if ground_truth is not None:
        log = log.replace(ground_truth=_read_ground_truth(ground_truth))
    result = run_calibration(log)
    result.save_yaml(out)
    _print_json(result.to_dict())


def _read_ground_truth(path: Path):
    from .io.tum import read_tum
    from .log import GroundTruth

    t, position, rpy = read_tum(path)
    return GroundTruth(t=t, position=position, orientation=rpy)


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

    from .evaluation.trajectory import trajectory_rmse
    from .trajectory import Trajectory

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
        f"NEES (pose, 6 dof): mean {result.nees_mean:.2f}, "
        f"{100 * result.nees_fraction_in_95:.0f} % inside the 95 % bound; {result.samples} samples"
    )


@app.command("map")
@user_errors
def map_command(
    log_path: Annotated[Path, typer.Argument(metavar="LOG", help="Bag or A50 JSON log.")],
    trajectory: Annotated[
        Path, typer.Option(help="Localization folder or trajectory.npz (with covariances).")
    ],
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")],
    method: Annotated[str | None, typer.Option(help="adaptive (default) | bki | csm")] = None,
    resolution: Annotated[float | None, typer.Option(help="Grid size, m (0.1).")] = None,
    length_scale: Annotated[
        float | None, typer.Option(help="Isotropic length scale of bki, m (0.15).")
    ] = None,
    prior: Annotated[Path | None, typer.Option(help="Seed from a saved map.npz.")] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Occupancy map of the seafloor from DVL beams and sonar ranges; writes map.npz, map.ply
    (occupied cell centres with mean and variance) and config.yaml.

    Example: `undertow map runs/a10/log --trajectory runs/a10/proposed --method adaptive
    --out runs/a10/map`
    """
    from .config import Settings
    from .mapping.config import MappingConfig
    from .mapping.run import map_log, save_map
    from .trajectory import Trajectory

    settings = Settings.from_yaml(config)
    options = {"method": method, "resolution": resolution, "length_scale": length_scale}
    given = {k: v for k, v in options.items() if v is not None}  # options win over the file
    cfg = MappingConfig.from_dict({**settings.mapping.model_dump(), **given})
    with _progress(quiet) as progress:
        progress.add_task(f"mapping ({cfg.method})", total=None)
        log = _load_log(log_path, topics, settings)
        result = map_log(log, Trajectory.load_npz(trajectory), cfg, prior=prior)
        save_map(result, out_dir)
    if not quiet:
        err.print(
            f"wrote {out_dir}/map.npz, map.ply ({result.metadata['occupied_cells']} occupied "
            "cells), config.yaml"
        )


@evaluate_app.command("map")
@user_errors
def evaluate_map_command(
    map_path: Annotated[Path, typer.Argument(metavar="MAP", help="map.npz, map.ply or folder.")],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth point cloud (PLY).")],
    threshold: Annotated[float, typer.Option(help="Occupied if mean > threshold.")] = 0.5,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Average cloud-to-cloud distance map -> ground truth (CloudCompare's C2C), occupied cells
    (the paper's Table IV) and the reverse distance (coverage).

    Example: `undertow evaluate map runs/a10/map runs/a10/ground_truth.ply --json`
    """
    from .evaluation.cloud import evaluate_map
    from .io.ply import read_ply
    from .mapping.grid import OccupancyMap

    if map_path.is_dir():
        map_path = map_path / "map.npz"
    resolution = None
    if map_path.suffix == ".ply":
        points, _ = read_ply(map_path)
    else:
        occupancy = OccupancyMap.load(map_path)
        points, resolution = occupancy.points(threshold), occupancy.resolution
    gt_points, _ = read_ply(ground_truth)
    result = evaluate_map(points, gt_points, resolution=resolution)
    if as_json:
        _print_json(result.to_dict())
        return
    for key, value in result.to_dict().items():
        console.print(
            f"{key:>28}: {value:.4f}" if isinstance(value, float) else f"{key:>28}: {value}"
        )


@app.command()
@user_errors
def reproduce(
    out_dir: Annotated[Path, typer.Option("--out", help="Results folder.")] = Path("results"),
    seeds: Annotated[int, typer.Option(help="Number of independent seeds (Monte Carlo).")] = 1,
    first_seed: Annotated[int, typer.Option(help="Seeds are first_seed, first_seed+1, ...")] = 0,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler for seeds after the first: local (default: a local cluster), "
            "threads, sync, or the address of a running scheduler (tcp://host:8786)."
        ),
    ] = None,
    rock_survey: Annotated[bool, typer.Option(help="Also run the rock survey.")] = True,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """The paper's experiments end to end: simulate, characterize, localize (4 variants), map
    (CSM, BKI, adaptive BKI), evaluate; tables with the paper's values, figures, report.html.

    Example: `undertow reproduce --seeds 10 --out results_mc`
    """
    from .experiments import StudySettings
    from .study import run_study

    if seeds < 1:
        raise UndertowError("--seeds must be at least 1")
    settings = StudySettings(rock_survey="rock-survey" if rock_survey else None)
    with _progress(quiet) as progress:
        task = progress.add_task("starting", total=None)
        result = run_study(
            out_dir,
            seeds=list(range(first_seed, first_seed + seeds)),
            scheduler=scheduler,
            settings=settings,
            progress=lambda msg: progress.update(task, description=msg),
        )
    if not quiet:
        from rich.markdown import Markdown

        console.print(Markdown(result.markdown))
        for seed, message in result.failures.items():
            err.print(f"[red]seed {seed} failed:[/] {message}", highlight=False)
        err.print(
            f"results in {out_dir}/ (tables.md, tables.json, figures/, runs/); report: "
            f"{result.report} ({result.wall_s:.0f} s)"
        )


@app.command()
@user_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Results folder.")] = Path("results"),
) -> None:
    """The main job with its defaults: `undertow reproduce --seeds 1 --out results`."""
    reproduce(out_dir=out_dir, seeds=1, first_seed=0, scheduler=None, rock_survey=True, quiet=False)


def main() -> None:  # pragma: no cover - console entry point
    app()


@app.command("characterize")
@user_errors
def characterize_command(
    logs: Annotated[list[Path], typer.Argument(metavar="LOG...", help="Runs with a wave probe.")],
    out: Annotated[
        Path | None, typer.Option("--out", help="Noise profile YAML for `undertow localize`.")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    config: ConfigOption = None,
    topics: TopicsOption = None,
) -> None:
    """Wave amplitude and frequency (wave probe) and the DVL noise per axis during the waves,
    about the true motion (the paper's Table I), plus the barometer's wave-induced depth noise.
    A calm run among the logs is the reference whose noise is subtracted.

    Example: `undertow characterize runs/calm/log runs/a10/log runs/a05/log --out profile.yaml`
    """
    from rich.table import Table

    from .characterize import characterize
    from .config import Settings

    settings = Settings.from_yaml(config)
    result = characterize([_load_log(p, topics, settings) for p in logs])
    if out is not None:
        result.profile.to_yaml(out)
    if as_json:
        _print_json({"runs": result.table(), "profile": result.profile.to_dict()})
        return
    table = Table(title="Wave characterization (DVL std in the DVL frame, m/s)")
    for col in ("run", "a (m)", "f (Hz)", "vx", "vy", "vz", "extra vx", "depth std (m)"):
        table.add_column(col, justify="right")
    for row in result.table():
        table.add_row(
            row["source"],
            _fmt(row["amplitude_m"]),
            _fmt(row["frequency_hz"]),
            *(_fmt(v) for v in row["dvl_std_mps"]),
            _fmt(row["dvl_extra_std_mps"][0]),
            _fmt(row["depth_std_m"]),
        )
    console.print(table)
    if result.calm is None:
        err.print("no calm run among the logs: the profile holds total, not extra, noise")


def _fmt(value, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
