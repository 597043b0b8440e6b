"""`undertow localize`, `undertow calibrate` and `undertow evaluate trajectory` as library
functions: file paths and settings in, a result object with the warnings and facts the command
prints out::

    from undertow.commands.localization import evaluate_trajectory_file, localize_file

    result = localize_file("runs/a10/log", variant="proposed", calibration="calm_cal.yaml",
                           out_dir="runs/a10/proposed")
    print(result.wave, result.wave_source, result.warnings)
    print(evaluate_trajectory_file(result.out_dir, "runs/a10/ground_truth.tum").errors.rmse)
    print(evaluate_trajectory_file(result.out_dir, "runs/a10/log", reference="dvl-dr").drift)
"""

from __future__ import annotations

import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

from .._util.atomic import check_output_file, check_output_folder
from ..errors import ConfigError
from ..estimation.calibration import Calibration, calibrate
from ..estimation.config import DEFAULT_GATE
from ..estimation.consistency import ConsistencyReport
from ..estimation.localizer import check_options, localize
from ..estimation.localizer_pieces import localize_pieces
from ..estimation.noise import NoiseProfile
from ..estimation.noise_physics import PHYSICS, outside_policy
from ..evaluation.drift import (
    ALIGNMENTS,
    CHECKPOINTS,
    REFERENCES,
    DriftResult,
    reference_track,
    trajectory_drift,
)
from ..evaluation.trajectory import PoseStates, TrajectoryErrors, trajectory_rmse
from ..io import PIECE_S, PieceChoice, piece_choice
from ..io.results import save_trajectory
from ..io.rosbag import bag_topics
from ..io.topics import LIVE_WAVE_TOPIC
from ..io.trajectory_stream import save_stored_trajectory
from ..io.tum import read_tum
from ..peers import UKF
from ..peers import resolve as resolve_estimator
from ..settings import Settings
from ..trajectory import Trajectory
from ..trajectory_chunks import NpzTrajectory, TrajectoryStore
from .common import as_settings, collect_warnings, load_log, load_log_pieces


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """A localized log: the trajectory (its metadata as written to ``config.yaml``), the wave
    condition the filter used and where it came from (``WAVE_GIVEN``, ``WAVE_DEFAULT`` of
    :mod:`undertow.estimation.localizer`, or the place in the log that recorded it), whether the
    variant added that condition's noise, the measurement counters, the warnings raised, and
    the folder written (None when none was asked for). The trajectory of a log filtered on
    disk (``chunked``) is the written trajectory.npz, read lazily."""

    trajectory: Trajectory | NpzTrajectory
    wave: str
    wave_source: str
    wave_noise_added: bool
    counts: dict
    warnings: tuple[str, ...]
    out_dir: Path | None = None

    @property
    def variant(self) -> str:
        return self.trajectory.variant

    @property
    def consistency(self) -> ConsistencyReport | None:
        """The innovations' consistency per sensor (:mod:`undertow.estimation.consistency`)."""
        return consistency_of(self.trajectory)


def localize_file(path: str | Path, settings: Settings | str | Path | None = None, *,
                  topics: str | Path | None = None, out_dir: str | Path | None = None,
                  overwrite: bool = False, profile=None, wave=None, calibration=None,
                  extrapolate: bool = False, smooth: bool = False, estimator: str = UKF,
                  chunked: bool | None = None, in_pieces: bool | None = None,
                  piece_s: float = PIECE_S, **overrides) -> LocalizationResult:  # fmt: skip
    """Localize the log at ``path`` with the paper's UKF (see
    :func:`~undertow.estimation.localizer.localize` for what it takes from the log and the
    calibration).

    ``settings``: a :class:`~undertow.settings.Settings`, a settings YAML path or None
    (defaults); ``overrides`` are :class:`~undertow.estimation.config.LocalizerConfig` fields
    (``variant``, ``output_rate_hz``, ``gate_probability``, ...) taking precedence over the
    settings' ``localizer`` section. ``profile``: noise profile (YAML path or NoiseProfile,
    default the paper's Table I); ``wave``: condition name or (amplitude, frequency), default
    the one the log records, else calm; ``"auto"`` estimates it over time from the log's own
    sensors (:mod:`undertow.seastate`); ``calibration``: a Calibration or its YAML file.
    ``estimator``: ``"ukf"`` (the paper's filter) or a peer of :data:`undertow.peers.ESTIMATORS`
    (``factor-graph``, ``isam2``, ``inekf``: the same sensors, noise and settings; no
    ``smooth``), recorded as ``estimator`` in the metadata.
    The options are checked before the log is read; with ``out_dir`` the folder is checked too
    and then written (``trajectory.tum``, ``trajectory.npz``, ``config.yaml``).

    ``chunked``: filter (and smooth) into a store on disk next to ``out_dir`` and write the
    folder from it chunk by chunk (:mod:`undertow.trajectory_chunks`; the same files); None
    (default) does so for a log of more than :data:`STORE_ABOVE_ROWS` filter rows written to
    ``out_dir`` at every state. The result's trajectory is then the written trajectory.npz,
    read lazily (:class:`~undertow.trajectory_chunks.NpzTrajectory`).

    ``in_pieces``: read and filter a ROS bag in pieces of ``piece_s`` seconds, the states on
    disk (:mod:`undertow.estimation.localizer_pieces`: memory bounded by a piece); None (default)
    does so for a bag too long to read whole (:func:`~undertow.io.piece_choice`: its index spans
    more than :data:`~undertow.io.PIECES_ABOVE_S`), False never. The whole log is read anyway
    for what needs it (``wave="auto"``, a live session's wave decisions, an output rate, a peer
    estimator, no ``out_dir``), said in one warning. A log read in pieces says so in one
    warning and records it in the metadata (``read_in_pieces``,
    :meth:`~undertow.io.PieceChoice.to_dict`)."""
    settings_path = None if isinstance(settings, Settings) else settings
    settings = as_settings(settings)
    params = {**settings.localizer_params(), **overrides}
    check_options(smooth, params)
    run = _estimator(estimator, smooth)
    if chunked and (out_dir is None or params.get("output_rate_hz") is not None):
        raise ConfigError("chunked: needs an output folder and every state (no output rate)")
    if out_dir is not None:
        inputs = [path, _path_or_none(profile), _path_or_none(calibration), settings_path, topics]
        check_output_folder(out_dir, overwrite, inputs=inputs)
    profile, calibration = _read_options(profile, wave, calibration, extrapolate)
    caught: list[str] = []
    with collect_warnings(caught):
        choice = _in_pieces(path, in_pieces, piece_s, (estimator, params, wave, out_dir))
        if choice.pieces:
            options = (profile, wave, calibration, extrapolate, smooth)
            trajectory = _localize_in_pieces(path, topics, settings, params, (out_dir, overwrite),
                                             options, choice)  # fmt: skip
    if choice.pieces:
        return _result(trajectory, caught, out_dir)
    with collect_warnings(caught):
        log = load_log(path, topics, settings)
        store = _store(chunked, log, params, out_dir) if estimator == UKF else None
        try:
            if estimator == UKF:
                trajectory = localize(log, profile=profile, wave=wave, calibration=calibration,
                                      extrapolate=extrapolate, smooth=smooth, store=store,
                                      **params)  # fmt: skip
            else:
                trajectory = run(log, profile=profile, wave=wave, calibration=calibration,
                                 extrapolate=extrapolate, **params)  # fmt: skip
            trajectory.metadata.setdefault("estimator", estimator)
            if store is not None:
                del log  # the log's arrays are not needed to write the folder
                save_stored_trajectory(trajectory, out_dir, overwrite)
                trajectory = NpzTrajectory.open(Path(out_dir) / "trajectory.npz")
        finally:
            if store is not None:
                store.remove()
    if out_dir is not None and store is None:
        save_trajectory(trajectory, out_dir, overwrite)
    return _result(trajectory, caught, out_dir)


def _result(trajectory, caught: list[str], out_dir) -> LocalizationResult:
    meta = trajectory.metadata
    return LocalizationResult(
        trajectory=trajectory,
        wave=meta["wave_condition"],
        wave_source=meta["wave_condition_source"],
        wave_noise_added=meta["wave_noise"] is not None,
        counts=meta["counts"],
        warnings=tuple(caught),
        out_dir=None if out_dir is None else Path(out_dir),
    )


#: filter rows (IMU, DVL, DR, barometer) above which `localize` keeps its states on disk (about
#: half an hour of a BlueROV2 log at 100 Hz: 0.5 GB of covariances)
STORE_ABOVE_ROWS = 200_000


def _in_pieces(path, in_pieces: bool | None, piece_s: float, run: tuple) -> PieceChoice:
    """Whether the log is read and filtered in pieces (:mod:`undertow.estimation.localizer_pieces`):
    a ROS bag as :func:`~undertow.io.piece_choice` decides (``in_pieces`` True or False as
    asked, None: by its size), localized by the UKF into ``out_dir`` (``run``: the estimator,
    localizer options, wave and output folder) at every state, with a wave condition that is
    not estimated from the log and no live session's wave decisions (those need the whole
    log); the choice stated in one warning when it is not today's whole read."""
    estimator, params, wave, out_dir = run
    choice = piece_choice(path, in_pieces, piece_s)
    if choice.pieces:
        needs = _needs_whole(path, estimator, params, wave, out_dir)
        choice = choice.blocked(needs) if needs else choice
    line = choice.line(path)
    if line:
        warnings.warn(f"localize: {line}", stacklevel=3)
    return choice


def _needs_whole(path, estimator: str, params: dict, wave, out_dir) -> str | None:
    """What of the run needs the whole log (None: nothing, the pieces can be read)."""
    if estimator != UKF:
        return f"the estimator {estimator}"
    if out_dir is None:
        return "a run without an output folder"
    if params.get("output_rate_hz") is not None:
        return "an output rate (--output-rate)"
    if is_auto(wave):
        return "--wave auto"
    if LIVE_WAVE_TOPIC in bag_topics(path):
        return "the replay of a live session's wave decisions"
    return None


#: what the first pass over a log read in pieces reads for the wave noise's site
SITE_STREAMS = ("pressure", "depth", "ground_truth", "dvl", "dvl_json")


def _localize_in_pieces(path, topics, settings: Settings, params: dict, out: tuple,
                        options: tuple, choice: PieceChoice) -> NpzTrajectory:  # fmt: skip
    """The folder ``out`` (out_dir, overwrite) of the log at ``path`` localized in pieces of
    ``choice.piece_s`` seconds, its states in a store beside it (removed after); the written
    trajectory.npz, read lazily. The wave noise's site, when a condition is extrapolated, is
    the whole log's, from a first pass over :data:`SITE_STREAMS`."""
    out_dir, overwrite = out
    profile, wave, calibration, extrapolate, smooth = options

    def read(streams=None):
        return load_log_pieces(path, choice.piece_s, topics, settings, streams)

    store = _new_store(out_dir)
    try:
        trajectory = localize_pieces(read(), store, profile=profile, wave=wave,
                                     calibration=calibration, extrapolate=extrapolate,
                                     smooth=smooth, site_pieces=lambda: _quiet(read(SITE_STREAMS)),
                                     **params)  # fmt: skip
        trajectory.metadata.setdefault("estimator", UKF)
        trajectory.metadata["read_in_pieces"] = choice.to_dict()
        save_stored_trajectory(trajectory, out_dir, overwrite)
    finally:
        store.remove()
    return NpzTrajectory.open(Path(out_dir) / "trajectory.npz")


def _quiet(pieces):
    """``pieces`` without their warnings (the pass that filters them states them)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield from pieces


def _new_store(out_dir) -> TrajectoryStore:
    """An empty store in a hidden folder beside ``out_dir``."""
    out = Path(out_dir).absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    return TrajectoryStore(tempfile.mkdtemp(prefix=f".{out.name}.states-", dir=out.parent))


def _store(chunked: bool | None, log, params: dict, out_dir) -> TrajectoryStore | None:
    """The on-disk store for the states (a hidden folder beside ``out_dir``), or None to keep
    them in memory: ``chunked`` as given, else by the log's filter rows (STORE_ABOVE_ROWS);
    never without ``out_dir`` or for a decimated output."""
    if out_dir is None or params.get("output_rate_hz") is not None:
        return None
    if chunked is None:
        streams = (log.imu, log.dvl, log.dead_reckoning, log.pressure)
        chunked = sum(len(s) for s in streams if s is not None) > STORE_ABOVE_ROWS
    if not chunked:
        return None
    return _new_store(out_dir)


def _estimator(name: str, smooth: bool):
    """The function of the estimator ``name`` (one ConfigError line: unknown, not importable,
    or a peer asked to smooth: the smoother is the UKF's)."""
    if name != UKF and smooth:
        raise ConfigError(
            f"--smooth smooths the UKF's output (URTS); the estimator {name} has no smoother "
            "option (factor-graph is itself a batch smoother): drop --smooth or use --estimator ukf"
        )
    return resolve_estimator(name)


def is_auto(wave) -> bool:
    """``wave`` asks for the condition estimated from the log itself (``--wave auto``)."""
    return isinstance(wave, str) and wave.strip().lower() == "auto"


def _path_or_none(value):
    return value if isinstance(value, (str, Path)) else None


def _read_options(profile, wave, calibration, extrapolate: bool | str):
    """The noise profile and calibration read and checked, and a given wave condition looked
    up in that profile, before any log is read: a wrong option fails at once, not after it
    (with the Localizer's outside policy: a condition outside the profile is extrapolated by
    default, at the log's depth once it is read)."""
    if not isinstance(profile, NoiseProfile):
        profile = NoiseProfile.paper() if profile is None else NoiseProfile.from_yaml(profile)
    if wave is not None and not is_auto(wave):
        with warnings.catch_warnings():  # its warnings are raised again where it is used
            warnings.simplefilter("ignore")
            profile.noise(wave, extrapolate=outside_policy(extrapolate, default=PHYSICS))
    if calibration is not None and not isinstance(calibration, Calibration):
        calibration = Calibration.from_yaml(calibration)
    return profile, calibration


@dataclass(frozen=True)
class CalibrationResult:
    """The calibration (what was estimated, and why the rest was not), the warnings raised and
    the YAML written (None when none was asked for)."""

    calibration: Calibration
    warnings: tuple[str, ...]
    out: Path | None = None


def calibrate_file(log_path: str | Path, ground_truth: str | Path | None = None,
                   settings: Settings | str | Path | None = None, *,
                   topics: str | Path | None = None,
                   out: str | Path | None = None) -> CalibrationResult:  # fmt: skip
    """Estimate mu_b, the IMU gyro bias and the DVL scale factor of the log at ``log_path``
    against its ground truth: the TUM file ``ground_truth`` when given, else the log's
    ground_truth stream (:func:`~undertow.estimation.calibration.calibrate`). With ``out``, the
    calibration YAML is written there (for ``localize_file(calibration=...)``)."""
    settings = as_settings(settings)
    if out is not None:
        check_output_file(out)
    caught: list[str] = []
    with collect_warnings(caught):
        truth = None if ground_truth is None else read_tum(ground_truth)  # before the log
        log = load_log(log_path, topics, settings)
        if truth is not None:
            log = log.replace(ground_truth=truth)
        calibration = calibrate(log)
    if out is not None:
        calibration.save_yaml(out)
    return CalibrationResult(calibration, tuple(caught), None if out is None else Path(out))


@dataclass(frozen=True)
class TrajectoryEvaluation:
    """A trajectory against a reference: per-axis RMSE and pose NEES against ground truth
    (``errors``, :class:`~undertow.evaluation.trajectory.TrajectoryErrors`), or its drift
    against a reference from a log (``drift``, :class:`~undertow.evaluation.drift.DriftResult`),
    or neither (no reference given); the filter's consistency report as ``undertow localize``
    recorded it (None for a trajectory without one), and the warnings raised."""

    errors: TrajectoryErrors | None
    warnings: tuple[str, ...]
    drift: DriftResult | None = None
    consistency: ConsistencyReport | None = None

    def to_dict(self) -> dict:
        """The reference's result (the RMSE and NEES, or the drift) with ``consistency``."""
        out = self.errors.to_dict() if self.errors is not None else {}
        if self.drift is not None:
            out = self.drift.to_dict()
        out["consistency"] = None if self.consistency is None else self.consistency.to_dict()
        return out


LOG_SUFFIXES = (".bag", ".mcap", ".db3", ".bin", ".log", ".tlog", ".json", ".jsonl")


def evaluate_trajectory_file(estimate: str | Path, ground_truth: str | Path | None = None,
                             align: str | None = None, *, reference: str | None = None,
                             settings: Settings | str | Path | None = None,
                             topics: str | Path | None = None,
                             checkpoints: int = CHECKPOINTS) -> TrajectoryEvaluation:  # fmt: skip
    """Evaluate a ``trajectory.npz`` (or its localization folder).

    Without ``reference``: against the ground-truth TUM file ``ground_truth``
    (:func:`~undertow.evaluation.trajectory.trajectory_rmse`; ``align``: none (default) |
    origin). With ``reference`` (gps | dvl-dr | autopilot): ``ground_truth`` is a log (any
    format :func:`~undertow.io.read_log` reads, with the ``topics`` / ``settings`` topic map)
    and the drift against that reference stream is measured
    (:func:`~undertow.evaluation.drift.trajectory_drift`; ``align``: start (default) | yaw |
    none; ``checkpoints`` for a continuous reference). With neither, only the consistency
    report. The options are checked before any file is read."""
    align = _check_evaluate_options(ground_truth, align, reference, checkpoints)
    if not isinstance(settings, Settings) and reference is not None:
        settings = Settings.from_yaml(settings)
    caught: list[str] = []
    errors = drift = None
    with collect_warnings(caught):
        trajectory = PoseStates.from_npz(estimate)  # chunk by chunk: the pose block of P
        if reference is not None:
            track = reference_track(load_log(ground_truth, topics, settings), reference)
            drift = trajectory_drift(trajectory, track, align, checkpoints)
        elif ground_truth is not None:
            errors = trajectory_rmse(trajectory, read_tum(ground_truth), align)
    return TrajectoryEvaluation(errors, tuple(caught), drift, consistency_of(trajectory))


def _check_evaluate_options(ground_truth, align, reference, checkpoints) -> str:
    """The alignment to use (its default for the kind of reference), or a one-line error."""
    if reference is not None:
        if ground_truth is None:
            raise ConfigError(f"--reference {reference}: give the log to take it from")
        if reference not in REFERENCES:
            raise ConfigError(
                f"--reference must be one of {', '.join(REFERENCES)}, not {reference!r}"
            )
        align = "start" if align is None else align
        if align not in ALIGNMENTS:
            raise ConfigError(
                f"align against a log's reference must be one of {', '.join(ALIGNMENTS)}, "
                f"not {align!r}"
            )
        if checkpoints < 1:
            raise ConfigError(f"--checkpoints must be at least 1, not {checkpoints}")
        return align
    align = "none" if align is None else align
    if align not in ("none", "origin"):  # checked before the files are read
        raise ConfigError(f"align must be 'none' or 'origin', not {align!r}")
    path = None if ground_truth is None else Path(ground_truth)
    if path is not None and (path.is_dir() or path.suffix.lower() in LOG_SUFFIXES):
        raise ConfigError(
            f"{path} is a log, not a ground-truth TUM file: choose the reference in it with "
            "--reference gps|dvl-dr|autopilot"
        )
    return align


def consistency_of(trajectory: Trajectory) -> ConsistencyReport | None:
    """The consistency report in ``trajectory``'s metadata (None when it has none: written
    before undertow recorded one, or not by ``undertow localize``)."""
    data = trajectory.metadata.get("consistency")
    if not isinstance(data, dict):
        return None
    try:
        return ConsistencyReport.from_dict(data)
    except (KeyError, TypeError, ValueError, AttributeError):
        return None


def gate_option(text: str | None) -> dict:
    """The localizer override for ``--gate TEXT``: {} when not given, ``gate_probability``
    None for ``off``, ``"default"`` for ``default`` (the conservative default gate), else a
    chi-square probability (checked with the other options; a non-number is one line)."""
    if text is None:
        return {}
    word = text.strip().lower()
    if word in ("off", "none", "null"):
        return {"gate_probability": None}
    if word == DEFAULT_GATE:
        return {"gate_probability": DEFAULT_GATE}
    try:
        return {"gate_probability": float(word)}
    except ValueError:
        raise ConfigError(
            f"--gate: expected off, default or a probability in (0, 1), not {text!r}"
        ) from None
