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

import numpy as np
import yaml

from .._util.atomic import check_output_folder, output_folder
from .._util.plain import to_plain
from ..errors import ConfigError
from ..evaluation.cloud import MapEvaluation, evaluate_map, map_threshold
from ..evaluation.surface import (
    CALIBRATION_KEYS,
    SurfaceEvaluation,
    cloud_spacing,
    evaluate_surface,
    hull_area,
)
from ..evaluation.truth import check_truth_options, load_truth, truth_kind
from ..io import PIECE_S, PieceChoice, piece_choice
from ..io.export.georef import from_latlon, from_projected, parse_origin, parse_utm
from ..io.export.geotiff import SUFFIXES as GEOTIFF_SUFFIXES
from ..io.export.geotiff_read import read_map_geotiff
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
from ..mapping.iho import check_order, withheld_notes
from ..mapping.run import (
    PIECE_METHODS,
    MappingResult,
    check_prior,
    map_log,
    map_pieces,
    tiled_map_metadata,
)
from ..mapping.samples import samples_from_config
from ..mapping.surface import Surface, map_surface, surface_from_points
from ..mapping.tiled import check_tiling, map_tiled
from ..mapping.tpu import with_wave
from ..occupancy import MAP_FILE, OccupancyMap
from ..settings import Settings
from ..trajectory import Trajectory
from ..trajectory_chunks import PoseTrack
from .common import as_settings, collect_warnings, load_log, load_log_pieces, npz_file

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
             in_pieces: bool | None = None, piece_s: float = PIECE_S,
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
    warning naming it.

    ``in_pieces``: read a ROS bag in pieces of ``piece_s`` seconds and map them in turn
    (:func:`~undertow.mapping.run.map_pieces`: memory bounded by a piece and the map); None
    (default) does so for a bag too long to read whole (:func:`~undertow.io.piece_choice`: its
    index spans more than :data:`~undertow.io.PIECES_ABOVE_S`), False never. The whole log is
    read anyway where the pieces cannot be mapped (a TUM trajectory, tiles, a method other
    than :data:`~undertow.mapping.run.PIECE_METHODS`), said in one warning. A log mapped in
    pieces says so in one warning and records it in the metadata (``read_in_pieces``)."""
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
        choice = _in_pieces(log_path, given, tiles, config, (in_pieces, piece_s))
        if choice.pieces:
            result = _map_in_pieces(log_path, given, topics, settings, config, prior, choice)
        else:
            result = None
    if result is None:
        tiling, out = (tiles, scheduler), (out_dir, overwrite)
        result, written = _map_whole(log_path, given, topics, settings, config, tiling, prior,
                                     out, caught)  # fmt: skip
        if written:  # tiled: written as the tiles finished
            return result
    result.warnings = caught
    if out_dir is not None:
        save_map(result.map, result.config.model_dump(mode="json"), result.metadata, out_dir,
                 overwrite, threshold=config.occupied_threshold)  # fmt: skip
    return result


def _in_pieces(log_path, given, tiles, config: MappingConfig, asked: tuple) -> PieceChoice:
    """Map in pieces (:func:`~undertow.mapping.run.map_pieces`): a ROS bag as
    :func:`~undertow.io.piece_choice` decides (``asked``: ``in_pieces`` True or False, None by
    its size; and ``piece_s``), with a trajectory.npz, no tiles and a method that allows it;
    the choice stated in one warning when it is not today's whole read."""
    in_pieces, piece_s = asked
    choice = piece_choice(log_path, in_pieces, piece_s)
    if choice.pieces and isinstance(given, TumInput):
        choice = choice.blocked("a TUM trajectory (its frame is detected from the log)")
    elif choice.pieces and tiles is not None:
        choice = choice.blocked("a tiled map (--tiles)")
    elif choice.pieces and config.method not in PIECE_METHODS:
        choice = choice.blocked(f"the {config.method} method (pieces: "
                                f"{' or '.join(PIECE_METHODS)})")  # fmt: skip
    line = choice.line(log_path)
    if line:
        warnings.warn(f"map: {line}", stacklevel=3)
    return choice


def _map_in_pieces(log_path, given, topics, settings: Settings, config: MappingConfig, prior,
                   choice: PieceChoice) -> MappingResult:  # fmt: skip
    pieces = load_log_pieces(log_path, choice.piece_s, topics, settings)
    trajectory, record = _trajectory_for_log(given, None, config)
    result = map_pieces(pieces, trajectory, config, prior=prior)
    result.metadata["trajectory"] = record
    result.metadata["read_in_pieces"] = choice.to_dict()
    return result


def _map_whole(log_path, given, topics, settings: Settings, config: MappingConfig, tiling,
               prior, out, caught: list[str]) -> tuple[MappingResult, bool]:  # fmt: skip
    """The whole log read and mapped, and whether it was written already (tiled, with its
    warnings)."""
    tiles, scheduler = tiling
    out_dir, overwrite = out
    with collect_warnings(caught):
        log = load_log(log_path, topics, settings)
        trajectory, record = _trajectory_for_log(given, log, config)
        if tiles is not None:
            return _map_tiled_file(log, trajectory, config, tiles, scheduler, out_dir,
                                   overwrite, caught, record), True  # fmt: skip
        result = map_log(log, trajectory, config, prior=prior)
    result.metadata["trajectory"] = record
    return result, False


def _read_trajectory(path, settings: Settings, stated: TrajectoryOptions | None):
    """A TUM file (by its content) as a :class:`TumInput` (finished against the log), else a
    trajectory.npz or its folder as ``(PoseTrack, its file)`` (what the mapper reads of it,
    :class:`~undertow.trajectory_chunks.PoseTrack`, read chunk by chunk); ``stated`` options
    (pose std, frame) with a trajectory.npz are an error: it carries its own covariance, in NED."""
    if is_tum_file(path):
        return read_tum_input(path, settings.trajectory, stated)
    file = npz_file(path, "trajectory.npz", _TRAJECTORY_NPZ)
    if stated is not None:
        raise ConfigError(
            f"pose_std and trajectory_frame (--pose-std, --trajectory-frame) apply to a TUM "
            f"trajectory; {file} carries its own covariance, in undertow's NED frame"
        )
    return PoseTrack.from_npz(file), file  # the poses and their variance, chunk by chunk


def _trajectory_for_log(given, log, config: MappingConfig) -> tuple[Trajectory | PoseTrack, dict]:
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
    config = with_wave(config, trajectory, log)  # once, so every tile maps with the same wave
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
    """Map metrics (C2C and cells, :class:`~undertow.evaluation.cloud.MapEvaluation`; the
    surface's, :class:`~undertow.evaluation.surface.SurfaceEvaluation`), the occupancy threshold
    used (None for a map.ply or GeoTIFF, thresholded when written) and where it came from,
    ``truth_z`` (how the truth's values were read), ``notes`` (the choices made, one line each)
    and ``warnings`` (an empty map, skipped lines)."""

    evaluation: MapEvaluation
    threshold: float | None
    threshold_from: str
    warnings: list[str] = field(default_factory=list)
    surface: SurfaceEvaluation | None = None
    notes: list[str] = field(default_factory=list)
    truth_z: str | None = None
    calibrated: bool = True
    std_kind: str = ""
    iho_order: str = ""
    withheld: int = 0

    def to_dict(self) -> dict:
        """Every metric, flat (C2C, cells, surface, F-scores, calibration: null for a map
        without a depth std, and what the std is, ``std_kind``), then the threshold and how
        the truth was read."""
        surface = {} if self.surface is None else self.surface.to_dict()
        surface["std_kind"] = self.std_kind or None
        surface.update(iho_order=self.iho_order or None, withheld_columns=self.withheld)
        if not self.calibrated:
            surface.update({k: None for k in (*CALIBRATION_KEYS, "std_kind")})
        return {**self.evaluation.to_dict(), **surface, "threshold": self.threshold,
                "threshold_from": self.threshold_from, "truth_z": self.truth_z}  # fmt: skip


@dataclass(frozen=True)
class _EvaluatedMap:
    """A map to evaluate: occupied points (C2C), its surface, frame (None: local, else the
    GeoTIFF's CRS), grid size, threshold and where it came from, whether it has a depth std."""

    points: np.ndarray
    surface: Surface
    frame: object | None
    resolution: float | None
    threshold: float | None
    threshold_from: str
    calibrated: bool


def _map_to_evaluate(map_path: Path, threshold: float | None, notes: list[str],
                     iho_order: str | None = None) -> _EvaluatedMap:  # fmt: skip
    """The map.npz, map.ply or GeoTIFF ``map_path`` as :class:`_EvaluatedMap`; the surface of
    a map.npz is ``map_surface(occupancy, threshold)``, of a map.ply its cell centres gridded
    (no std), of a GeoTIFF its depth and std bands (held to an IHO order when exported)."""
    suffix = map_path.suffix.lower()
    if suffix in (".ply", *GEOTIFF_SUFFIXES) and iho_order is not None:
        raise ConfigError(
            f"--iho-order applies to a map.npz; {map_path} holds the columns kept when it was "
            "written (give the map.npz, or leave --iho-order out)"
        )
    if suffix in (".ply", *GEOTIFF_SUFFIXES) and threshold is not None:
        raise ConfigError(
            f"threshold applies to a map.npz; {map_path} holds the cells already "
            "thresholded when it was written (give the map.npz, or leave the threshold out)"
        )
    if suffix in GEOTIFF_SUFFIXES:
        grid = read_map_geotiff(map_path)
        depth, std, cover = (grid.bands[k] for k in ("depth", "std", "coverage"))
        surface = Surface(grid.x0, grid.y0, grid.resolution, depth, std, cover > 0,
                          str(grid.tags.get("UNDERTOW_STD", "")),
                          str(grid.tags.get("UNDERTOW_IHO_ORDER", "")))  # fmt: skip
        notes.append(f"{map_path}: C2C and cells are the GeoTIFF's cells with data")
        return _EvaluatedMap(surface.points(), surface, grid.crs, grid.resolution, None,
                             "the GeoTIFF (thresholded when it was exported)", True)  # fmt: skip
    if suffix == ".ply":
        points = np.asarray(read_ply(map_path)[0], dtype=float).reshape(-1, 3)
        notes.append(f"{map_path}: a map.ply holds no depth std: calibration null")
        return _EvaluatedMap(points, _ply_surface(points), None, None, None,
                             "the map.ply (thresholded when it was written)", False)  # fmt: skip
    occupancy = OccupancyMap.load(map_path)
    threshold, threshold_from = map_threshold(occupancy, threshold)
    surface = map_surface(occupancy, threshold, iho_order=iho_order)
    notes.extend(withheld_notes(surface.iho_order, surface.withheld))
    return _EvaluatedMap(occupancy.points(threshold), surface, None, occupancy.resolution,
                         threshold, threshold_from, True)  # fmt: skip


def _ply_surface(points: np.ndarray) -> Surface:
    """The surface of a map.ply's cell centres: gridded at their spacing (of distinct x-y
    columns), the shallowest per column, no std."""
    if not len(points):
        empty = np.zeros((0, 0))
        return Surface(0.0, 0.0, 1.0, empty, empty, empty.astype(bool))
    columns = np.unique(points[:, :2], axis=0)
    spacing = cloud_spacing(np.column_stack([columns, np.zeros(len(columns))]))
    gridded = surface_from_points(points, spacing)
    return dataclasses.replace(gridded, std=np.full(gridded.shape, np.nan))


def _map_georeference(origin, utm):
    """The map's :class:`~undertow.io.export.georef.Georeference` from ``origin`` ("LAT,LON" or
    (lat, lon)) or ``utm`` ("E,N,ZONE" or (e, n, zone)), as `undertow export` takes them."""
    if origin is not None and utm is not None:
        raise ConfigError("give one of --origin LAT,LON and --utm E,N,ZONE, not both")
    if origin is not None:
        return parse_origin(origin) if isinstance(origin, str) else from_latlon(*origin)
    if utm is not None:
        return parse_utm(utm) if isinstance(utm, str) else from_projected(*utm)
    return None


def evaluate_map_file(map_path: str | Path, ground_truth_path: str | Path,
                      threshold: float | None = None, *, origin=None, utm=None,
                      truth_z: str | None = None,
                      truth_frame: str | None = None,
                      iho_order: str | None = None) -> MapEvaluationResult:  # fmt: skip
    """A map (``map.npz``, its folder, a ``map.ply`` or an exported GeoTIFF) against a ground
    truth (a PLY cloud, an XYZ file or a GeoTIFF bathymetry, :mod:`undertow.evaluation.truth`):
    cloud-to-cloud distance and cells (:func:`~undertow.evaluation.cloud.evaluate_map`) and the
    surface's metrics and calibration (:func:`~undertow.evaluation.surface.evaluate_surface`)
    over the truth inside the hull of the map's covered columns
    (:func:`~undertow.evaluation.surface.hull_area`). Occupied cells of a map.npz: mean >
    ``threshold`` in (0, 1), by default the one the map was made with. ``origin``/``utm``: the
    map's origin, for a truth (or map) with a CRS; ``truth_z`` (depth | elevation) and
    ``truth_frame`` (local | projected, XYZ) override what is detected. ``iho_order``: the
    IHO S-44 order a map.npz's surface is held to (:func:`~undertow.mapping.surface.
    map_surface`; None: its default, "none": every column)."""
    if threshold is not None and not 0.0 < threshold < 1.0:
        raise ConfigError(f"threshold must be in (0, 1), got {threshold}")
    if iho_order is not None:
        check_order(iho_order)
    check_truth_options(truth_kind(ground_truth_path), truth_z, truth_frame)
    georef = _map_georeference(origin, utm)
    map_path = Path(map_path)
    map_path = map_path / "map.npz" if map_path.is_dir() else map_path
    notes: list[str] = []
    caught: list[str] = []
    loaded = _map_to_evaluate(map_path, threshold, notes, iho_order)
    if len(loaded.points) == 0:
        caught.append(f"{map_path}: the map has no points")
    with collect_warnings(caught):
        truth = load_truth(ground_truth_path, loaded.frame, georef, truth_z=truth_z,
                           truth_frame=truth_frame, near=_extent(loaded.surface))  # fmt: skip
    evaluation = evaluate_map(loaded.points, truth.cloud, resolution=loaded.resolution)
    area = hull_area(loaded.surface, truth.reference)
    surface = evaluate_surface(loaded.surface, truth.reference, area=area)
    return MapEvaluationResult(evaluation, loaded.threshold, loaded.threshold_from, caught,
                               surface, notes + truth.notes, truth.z, loaded.calibrated,
                               loaded.surface.std_kind, loaded.surface.iho_order,
                               loaded.surface.withheld)  # fmt: skip


def _extent(surface: Surface):
    """(x_min, x_max, y_min, y_max) of the surface's covered cells, None without any."""
    pts = surface.points()
    if not len(pts):
        return None
    half = surface.resolution / 2
    (x0, y0), (x1, y1) = pts[:, :2].min(axis=0) - half, pts[:, :2].max(axis=0) + half
    return float(x0), float(x1), float(y0), float(y1)
