"""`undertow map` and `undertow evaluate map` as library functions: file paths and settings in,
a result object with the warnings and facts the command prints out.

    >>> result = map_file("runs/a10/log", "runs/a10/proposed", method="adaptive",
    ...                   out_dir="runs/a10/map")                      # doctest: +SKIP
    >>> evaluate_map_file("runs/a10/map", "runs/a10/ground_truth.ply").to_dict()  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import warnings
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .._util.atomic import check_output_folder, output_folder
from .._util.plain import to_plain
from ..errors import ConfigError, DataError
from ..evaluation.cloud import MapEvaluation, evaluate_map, map_threshold
from ..io.ply import read_ply, write_map_ply
from ..io.results import save_map
from ..io.trajectory_input import (
    TrajectoryOptions,
    TumInput,
    is_tum_file,
    read_tum_input,
    tum_trajectory,
)
from ..mapping.config import MappingConfig
from ..mapping.run import MappingResult, check_prior, map_log, tiled_map_metadata
from ..mapping.samples import samples_from_config
from ..mapping.tiled import check_tiling, map_tiled
from ..occupancy import MAP_FILE, OccupancyMap
from ..settings import Settings
from ..trajectory import Trajectory
from .common import as_settings, collect_warnings, load_log, npz_file

#: options that only one mapping method uses: giving one for another method is an error
METHOD_OPTIONS = {"length_scale": "bki", "variance_bounds": "adaptive"}
_TRAJECTORY_NPZ = (
    "a trajectory.npz written by `undertow localize` (or its folder), or a TUM file (t tx ty tz "
    "qx qy qz qw)"
)


def mapping_config(settings: Settings, overrides: dict) -> MappingConfig:
    """The settings' mapping section with ``overrides`` (MappingConfig fields) on top, checked
    once; an override that only another method uses (:data:`METHOD_OPTIONS`) is an error."""
    config = MappingConfig.from_dict({**settings.mapping.model_dump(), **overrides})
    for key, applies in METHOD_OPTIONS.items():
        if key in overrides and config.method != applies:
            raise ConfigError(f"{key} applies to the {applies} method, not {config.method}")
    return config


def map_file(log_path: str | Path, trajectory_path: str | Path,
             settings: Settings | str | Path | None = None, *, topics: str | Path | None = None,
             prior: OccupancyMap | str | Path | None = None, out_dir: str | Path | None = None,
             overwrite: bool = False, tiles: float | None = None, scheduler: str | None = None,
             pose_std=None, trajectory_frame: str | None = None,
             **overrides) -> MappingResult:  # fmt: skip
    """Occupancy map of the seafloor from a log's DVL beams and sonar ranges along a trajectory
    (a ``trajectory.npz`` with covariances, or its localization folder; or a TUM file, told by
    its content, with its pose standard deviations as columns or stated: ``pose_std`` (3 or 6
    values, m and rad) or the settings' ``trajectory`` section, and its frame detected from the
    log's depth or stated, ``trajectory_frame`` "ned" or "enu";
    :mod:`undertow.io.trajectory_input`). ``result.metadata["trajectory"]`` records the file,
    format, frame and covariance used.

    ``settings``: a :class:`~undertow.settings.Settings`, a settings YAML path or None
    (defaults); ``overrides`` are :class:`~undertow.mapping.config.MappingConfig` fields
    (``method``, ``resolution``, ``length_scale``, ``variance_bounds``, ...) taking precedence
    over the settings' ``mapping`` section. ``prior``: a map (or ``map.npz``, or its folder) to
    seed from. With ``out_dir``, the folder is checked before any work and then written
    (:func:`~undertow.io.results.save_map`). Warnings are returned in ``result.warnings``.

    ``tiles``: map in square tiles of this size (m) as Dask tasks on ``scheduler`` ("local",
    "threads", "sync" or ``tcp://host:port``; :func:`~undertow.mapping.tiled.map_tiled`), the
    tiles also written to ``out_dir/tiles``; a tile that fails twice is left out with a
    warning naming it."""
    settings_path = None if isinstance(settings, Settings) else settings
    settings = as_settings(settings)
    config = mapping_config(settings, overrides)  # the options first, then the files
    check_tiling(tiles, scheduler, prior, config)
    if out_dir is not None:
        given_prior = None if isinstance(prior, OccupancyMap) else prior
        inputs = [log_path, trajectory_path, given_prior, settings_path, topics]
        check_output_folder(out_dir, overwrite, inputs=inputs)
    stated = TrajectoryOptions.stated(pose_std, trajectory_frame)
    if prior is not None and not isinstance(prior, OccupancyMap):
        prior = npz_file(prior, "map.npz", MAP_FILE, "prior ")
    check_prior(prior, config)
    caught: list[str] = []
    with collect_warnings(caught):
        given = _read_trajectory(trajectory_path, settings, stated)  # before the (longer) log
        log = load_log(log_path, topics, settings)
        trajectory, record = _trajectory_for_log(given, log, config)
        if tiles is not None:
            return _map_tiled_file(log, trajectory, config, tiles, scheduler, out_dir,
                                   overwrite, caught, record)  # fmt: skip
        result = map_log(log, trajectory, config, prior=prior)
    result.warnings = caught
    result.metadata["trajectory"] = record
    if out_dir is not None:
        save_map(result.map, config.model_dump(mode="json"), result.metadata, out_dir, overwrite,
                 threshold=config.occupied_threshold)  # fmt: skip
    return result


def _read_trajectory(path, settings: Settings, stated: TrajectoryOptions | None):
    """A TUM file (by its content) as a :class:`TumInput` (finished against the log), else a
    trajectory.npz or its folder as ``(Trajectory, its file)``; ``stated`` options (pose std,
    frame) with a trajectory.npz are an error: it carries its own covariance, in NED."""
    if is_tum_file(path):
        return read_tum_input(path, settings.trajectory, stated)
    file = npz_file(path, "trajectory.npz", _TRAJECTORY_NPZ)
    if stated is not None:
        raise ConfigError(
            f"pose_std and trajectory_frame (--pose-std, --trajectory-frame) apply to a TUM "
            f"trajectory; {file} carries its own covariance, in undertow's NED frame"
        )
    return Trajectory.load_npz(file), file


def _trajectory_for_log(given, log, config: MappingConfig) -> tuple[Trajectory, dict]:
    """The trajectory to map ``log`` with and what config.yaml records of it (file, format,
    frame, covariance); a constant pose std under the adaptive kernel's session
    normalization is a warning: every sample gets the same kernel (l_min)."""
    if not isinstance(given, TumInput):
        trajectory, file = given
        return trajectory, {"file": str(file), "format": "trajectory.npz (undertow localize)",
                            "frame": "ned", "frame_source": "undertow's own",
                            "covariance": "the trajectory's own (P)"}  # fmt: skip
    if given.constant and config.method == "adaptive" and config.variance_bounds is None:
        warnings.warn(
            f"{given.path}: a constant pose std gives every sample the same adaptive kernel "
            "(l_min) under session normalization; --variance-bounds places it between fixed "
            "bounds",
            stacklevel=2,
        )
    return tum_trajectory(given, log)


def _map_tiled_file(log, trajectory, config: MappingConfig, tiles: float, scheduler,
                    out_dir, overwrite: bool, caught: list[str],
                    record: dict) -> MappingResult:  # fmt: skip
    """:func:`map_file` with ``tiles``: samples, tiles on Dask, merged map; with ``out_dir``
    the tiles are written to ``out_dir/tiles`` as they finish, then the merged map."""
    with collect_warnings(caught):
        samples = samples_from_config(log, trajectory, config)
        with output_folder(out_dir, overwrite) if out_dir is not None else nullcontext() as out:
            tile_dir = None if out is None else out / "tiles"
            tiled = map_tiled(samples, config, tiles, scheduler=scheduler, tile_dir=tile_dir)
            metadata = tiled_map_metadata(tiled, samples, log, trajectory, config)
            metadata["trajectory"] = record
            if out is not None:
                _write_map(out, tiled.map, config, metadata)
    occupancy = dataclasses.replace(
        tiled.map,
        metadata={**tiled.map.metadata, "occupied_threshold": config.occupied_threshold},
    )
    result = MappingResult(occupancy, config, metadata)
    result.warnings = caught
    return result


def _write_map(out: Path, occupancy: OccupancyMap, config: MappingConfig, metadata: dict) -> None:
    """map.npz, map.ply and config.yaml into ``out`` (as :func:`save_map` does)."""
    occupancy.save(out / "map.npz")
    write_map_ply(out / "map.ply", occupancy, threshold=config.occupied_threshold)
    doc = {"mapping": config.model_dump(mode="json"), "result": to_plain(metadata)}
    (out / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


@dataclass(frozen=True)
class MapEvaluationResult:
    """Map metrics and the occupancy threshold used (None for a map.ply, thresholded when it
    was written), where that threshold came from, and warnings (an empty map)."""

    evaluation: MapEvaluation
    threshold: float | None
    threshold_from: str
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {**self.evaluation.to_dict(), "threshold": self.threshold,
                "threshold_from": self.threshold_from}  # fmt: skip


def evaluate_map_file(map_path: str | Path, ground_truth_path: str | Path,
                      threshold: float | None = None) -> MapEvaluationResult:  # fmt: skip
    """Cloud-to-cloud distance of a map (``map.npz``, its folder, or a ``map.ply``) to a
    ground-truth PLY cloud (:func:`~undertow.evaluation.cloud.evaluate_map`). Occupied cells of
    a map.npz: mean > ``threshold`` in (0, 1), by default the one the map was made with."""
    if threshold is not None and not 0.0 < threshold < 1.0:
        raise ConfigError(f"threshold must be in (0, 1), got {threshold}")
    map_path = Path(map_path)
    map_path = map_path / "map.npz" if map_path.is_dir() else map_path
    notes: list[str] = []
    resolution, threshold_from = None, "the map.ply (thresholded when it was written)"
    if map_path.suffix.lower() == ".ply":
        if threshold is not None:
            raise ConfigError(
                f"threshold applies to a map.npz; {map_path} holds the cells already "
                "thresholded when it was written (give the map.npz, or leave the threshold out)"
            )
        points = read_ply(map_path)[0]
        if len(points) == 0:
            notes.append(f"{map_path}: the map has no points")
    else:
        occupancy = OccupancyMap.load(map_path)
        threshold, threshold_from = map_threshold(occupancy, threshold)
        points = occupancy.points(threshold)
        resolution = occupancy.resolution
    gt_points = read_ply(ground_truth_path)[0]
    if len(gt_points) == 0:
        raise DataError(f"{ground_truth_path}: the ground-truth cloud has no points")
    evaluation = evaluate_map(points, gt_points, resolution=resolution)
    return MapEvaluationResult(evaluation, threshold, threshold_from, notes)
