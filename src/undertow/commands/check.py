"""`undertow check LOG`: is this log ready to localize and map, and what do I set?

:func:`check_file` reads the log the way ``localize`` and ``map`` will (the same reader, topic
map, time base and unit resolution), then reports per stream found: its topic and type, rate,
gaps, invalid share, the units and references evidence, and what the filter or the mapper will
use it for; the streams missing for each job; and the settings lines that fix each problem. For
a bag it scores every topic by message type and name (:mod:`undertow.io.topic_guess`) and
proposes a topic map. ``write_config`` writes the proposed settings file, so that
``undertow localize LOG --config FILE`` runs on what was found::

    from undertow.commands.check import check_file

    result = check_file("SO_bag", write_config="robot.yaml")
    print(result.ready, result.reason, [p.fix for p in result.problems])
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .._util.atomic import atomic_path, check_output_file
from .._util.plain import json_safe
from ..errors import MissingStreamError, UndertowError
from ..estimation.config import LocalizerConfig
from ..estimation.localizer import sensor_coverage
from ..estimation.rows import depth_reference
from ..estimation.sensor_checks import dvl_pitch_offset, imu_axes
from ..io import detect_format
from ..io.rosbag import bag_topics
from ..io.topic_guess import propose_topics
from ..log import Log
from ..settings import Settings
from .common import as_settings, collect_warnings, load_log

PITCH_OFFSET_RAD = math.radians(3.0)
#: a gap is an interval longer than this many median intervals (and than GAP_MIN_S)
GAP_FACTOR = 5.0
GAP_MIN_S = 0.5

#: what each stream is used for
USE = {
    "dvl": "filter: body velocity (and its beam ranges for the map)",
    "dead_reckoning": "filter: the DVL's attitude (and its position as a reference: "
    "evaluate --reference dvl-dr)",
    "imu": "filter: gyro rates",
    "pressure": "filter: depth (d = (p - p_surface) / (rho g))",
    "depth": "reference: the vehicle's own depth, compared with the pressure's",
    "sonar": "map: single-beam ranges",
    "multibeam": "map: multibeam detections",
    "gps": "reference: position fixes (evaluate --reference gps)",
    "autopilot": "reference: the autopilot's own estimate (evaluate --reference autopilot)",
    "ground_truth": "evaluation: ground truth",
    "wave_probe": "waves: surface elevation (a tank's probe)",
}


@dataclass(frozen=True)
class StreamCheck:
    """One stream as the filter and the mapper will see it."""

    stream: str
    topic: str | None
    msgtype: str | None
    messages: int
    rate_hz: float
    span_s: float
    gaps: int
    max_gap_s: float
    invalid_share: float
    use: str
    evidence: str = ""


@dataclass(frozen=True)
class Problem:
    """A problem found and the settings lines that fix it (empty when none can)."""

    what: str
    fix: str = ""


@dataclass(frozen=True)
class CheckResult:
    """What :func:`check_file` found (see the module docstring). ``ready``: the log can be
    localized as read; ``reason``: why not (one line) or what the filter will run on."""

    path: Path
    format: str
    ready: bool
    reason: str
    time_base: dict
    streams: list[StreamCheck]
    missing: list[str]
    problems: list[Problem]
    proposed_topics: dict[str, dict]
    settings: dict
    warnings: tuple[str, ...] = field(default_factory=tuple)
    written: Path | None = None

    def to_dict(self) -> dict:
        data = asdict(self)
        data["path"], data["written"] = str(self.path), self.written and str(self.written)
        return json_safe(data)


def _gaps(t: np.ndarray) -> tuple[int, float]:
    if t.size < 3:
        return 0, math.nan
    dt = np.diff(t)
    median = float(np.median(dt))
    limit = max(GAP_FACTOR * median, GAP_MIN_S)
    return int(np.sum(dt > limit)), float(dt.max())


def _evidence(name: str, log: Log) -> str:
    meta = log.metadata
    if name == "imu" and isinstance(meta.get("imu_units"), dict):
        u = meta["imu_units"]
        action = " (converted to rad/s)" if u.get("converted") else ""
        return f"gyro unit {u.get('unit')}{action}: {u.get('evidence')}"
    if name == "pressure":
        rho, p0 = depth_reference(log, LocalizerConfig())
        source = meta.get("surface_pressure_source", "standard atmosphere")
        return f"surface pressure {p0:,.0f} Pa ({source}); water {rho:g} kg/m^3"
    if name == "depth":
        line = f"z {meta.get('depth_z', 'positive down')}"
        rms = depth_agreement(log)
        if rms is not None:
            line += f"; RMS {rms:.3f} m against the depth from the pressure"
        return line
    if name == "gps" and log.gps is not None:
        return f"origin {meta.get('gps_origin', 'first fix')}"
    return ""


def depth_agreement(log: Log) -> float | None:
    """RMS (m) of the depth from the pressure (the log's resolved surface pressure and water)
    minus the vehicle's own depth report interpolated at the pressure's times (None without
    both)."""
    if log.pressure is None or log.depth is None or len(log.depth) < 2:
        return None
    d = log.pressure.depth(*depth_reference(log, LocalizerConfig()))
    own = np.interp(log.pressure.t, log.depth.t, log.depth.depth)
    inside = (log.pressure.t >= log.depth.t[0]) & (log.pressure.t <= log.depth.t[-1])
    diff = (d - own)[inside & np.isfinite(d) & np.isfinite(own)]
    return float(np.sqrt(np.mean(diff**2))) if diff.size else None


def _stream_checks(log: Log, types: dict) -> list[StreamCheck]:
    topics = log.metadata.get("topics", {})
    out = []
    for name, s in log.streams().items():
        topic = topics.get(name)
        gaps, max_gap = _gaps(np.asarray(s.t))
        out.append(StreamCheck(
            stream=name, topic=topic, msgtype=types.get(topic, (None,))[0] if topic else None,
            messages=len(s), rate_hz=s.rate_hz, span_s=float(s.t[-1] - s.t[0]) if len(s) else 0.0,
            gaps=gaps, max_gap_s=max_gap, invalid_share=s.invalid_count() / max(len(s), 1),
            use=USE.get(name, ""), evidence=_evidence(name, log),
        ))  # fmt: skip
    return out


def _time_base(meta: dict) -> dict:
    """The reader's time base as a dict (a reader with one clock may state it in words)."""
    tb = meta.get("time_base") or {}
    return tb if isinstance(tb, dict) else {"base": "log", "reason": str(tb)}


def _missing(log: Log) -> list[str]:
    has = set(log.streams())
    missing = []
    if "dvl" not in has:
        missing.append("localize: no DVL velocity (stream dvl)")
    if not {"imu", "dead_reckoning"} & has:
        missing.append("localize: no orientation source (an IMU gyro or the DVL's dead reckoning)")
    if "pressure" not in has:
        missing.append("localize: no barometer (depth from DVL integration only)")
    if "dead_reckoning" not in has:
        missing.append("localize: no DVL dead reckoning (the DR bias states are held at 0)")
    if "imu" not in has:
        missing.append("localize: no IMU gyro (the gyro bias states are held at 0)")
    beams = log.dvl is not None and np.isfinite(np.asarray(log.dvl.beam_range)).any()
    if not ({"sonar", "multibeam"} & has or beams):
        missing.append("map: no ranges (a sonar, a multibeam or DVL beam ranges)")
    if not {"gps", "autopilot", "dead_reckoning", "ground_truth"} & has:
        missing.append("evaluate: no reference (GPS, DVL dead reckoning, autopilot, ground truth)")
    return missing


def _problems_and_settings(log: Log, fmt: str, settings: Settings) -> tuple:
    """(problems with their fixes, the proposed settings file as a dict with comments)."""
    meta = log.metadata
    problems: list[Problem] = []
    proposed: dict = {}
    comments: dict = {}
    if fmt in ("ros1", "ros2"):
        used = meta.get("topics", {})
        proposed["topics"] = {s: used[s] for s in used if s != "tf_static"}
        guessed = meta.get("topics_guessed", {})
        if guessed:
            lines = "\n".join(f"  {s}: {t}" for s, t in guessed.items())
            problems.append(Problem(
                "topics named unlike the defaults, chosen by message type and name: "
                + ", ".join(f"{s}={t}" for s, t in guessed.items()),
                f"topics:\n{lines}",
            ))  # fmt: skip
    section: dict = {}
    tb = _time_base(meta)
    if tb.get("mixed_clocks"):
        section["time"] = tb["base"]
        comments["log.time"] = tb.get("reason", "")
        fix = f"log: {{time: {tb['base']}}}"
        problems.append(Problem(f"mixed clocks: {tb.get('reason')}", fix))
    units = meta.get("imu_units")
    if isinstance(units, dict) and units.get("unit") in ("deg/s", "ambiguous"):
        section["imu_units"] = "deg/s"
        comments["log.imu_units"] = units.get("evidence", "")
        if units.get("how") != "settings":
            problems.append(Problem(f"gyro unit: {units.get('evidence')}",
                                    "log: {imu_units: deg/s}"))  # fmt: skip
    source = str(meta.get("surface_pressure_source", ""))
    if log.pressure is not None and "settings" not in source:
        p0 = meta.get("surface_pressure_pa")
        if isinstance(p0, float) and not source.startswith("standard atmosphere"):
            section["surface_pressure_pa"] = round(p0, 1)
            comments["log.surface_pressure_pa"] = source
        elif source.startswith("standard atmosphere"):
            problems.append(Problem(
                f"surface pressure: {source}; depths are relative to 101,325 Pa",
                "log: {surface_pressure_pa: PA}  # the pressure at the surface, Pa",
            ))  # fmt: skip
    if log.pressure is not None:
        section["water"] = meta.get("water", "fresh")
        comments.setdefault("log.water", "fresh (998 kg/m^3) or salt (1025): set what you dove in")
    if section:
        proposed["log"] = section
    _cross_checks(log, settings, problems, proposed, comments)
    return problems, proposed, comments


def _cross_checks(log: Log, settings: Settings, problems: list, proposed: dict,
                  comments: dict) -> None:  # fmt: skip
    """The sensors against each other (:mod:`undertow.estimation.sensor_checks`): the IMU's
    axes against the DVL's yaw, the DVL's pitch against the pressure's depth rate."""
    with np.errstate(all="ignore"):
        axes = imu_axes(log)
    flipped = abs(abs(log.mounting.imu.rotation[0]) - math.pi) < 0.1
    if axes is not None and axes["z_up"] != flipped:
        rotation = [0.0, 0.0, 0.0] if flipped else [math.pi, 0.0, 0.0]
        proposed.setdefault("mounting", {})["imu"] = {"rotation": rotation}
        comments["mounting.imu"] = axes["evidence"]
        problems.append(Problem(f"IMU axes: {axes['evidence']}",
                                f"mounting: {{imu: {{rotation: {rotation}}}}}"))  # fmt: skip
    if log.pressure is None:
        return
    rho, p0 = depth_reference(log, settings.localizer)
    with np.errstate(all="ignore"):
        pitch = dvl_pitch_offset(log, rho, p0)
    if pitch is None or abs(pitch["offset_rad"]) < PITCH_OFFSET_RAD:
        return
    std = list(settings.localizer.dr_orientation_std_rad)
    scatter = round(max(pitch["scatter_rad"], std[1]), 4)
    bias = [0.0, round(pitch["offset_rad"], 4), 0.0]
    local = proposed.setdefault("localizer", {})
    local["dr_bias_rad"] = bias
    local["dr_orientation_std_rad"] = [scatter, scatter, std[2]]
    comments["localizer.dr_bias_rad"] = pitch["evidence"] + ": its mean, the DR bias's prior"
    comments["localizer.dr_orientation_std_rad"] = "its scatter, the DVL's roll and pitch accuracy"
    problems.append(Problem(
        f"DVL attitude: {pitch['evidence']}",
        f"localizer: {{dr_bias_rad: {bias}, dr_orientation_std_rad: {[scatter, scatter, std[2]]}}}",
    ))  # fmt: skip


def settings_yaml(proposed: dict, comments: dict, source: str) -> str:
    """The proposed settings as YAML, each detected value with its evidence as a comment."""
    lines = [f"# settings proposed by `undertow check` for {source}", ""]
    for key, value in proposed.items():
        lines.append(f"{key}:")
        for sub, v in value.items():
            text = yaml.safe_dump({sub: v}, default_flow_style=True, width=1000).strip()
            text = text[1:-1] if text.startswith("{") else text
            note = comments.get(f"{key}.{sub}", "")
            lines.append(f"  {text}" + (f"  # {note}" if note else ""))
    return "\n".join(lines) + "\n"


def check_file(path: str | Path, settings: Settings | str | Path | None = None, *,
               topics: str | Path | None = None, time: str | None = None,
               write_config: str | Path | None = None) -> CheckResult:  # fmt: skip
    """Check the log at ``path`` (see the module docstring); with ``write_config``, write the
    proposed settings file there (a new file, written whole or not at all)."""
    settings = as_settings(settings)
    if write_config is not None:
        check_output_file(write_config)
    fmt = detect_format(path)
    types = bag_topics(path) if fmt in ("ros1", "ros2") else {}
    caught: list[str] = []
    with collect_warnings(caught):
        log = load_log(path, topics, settings, time=time)
        streams = _stream_checks(log, types)
        ready, reason = True, ""
        try:
            unobserved, _ = sensor_coverage(log, LocalizerConfig())
            reason = "ready to localize" + (f" ({len(unobserved)} states left to the motion "
                                           "model)" if unobserved else "")  # fmt: skip
        except (MissingStreamError, UndertowError) as exc:
            ready, reason = False, str(exc)
    problems, proposed, comments = _problems_and_settings(log, fmt, settings)
    guess = propose_topics({t: m for t, (m, _) in types.items()}) if types else {}
    written = None
    if write_config is not None:
        text = settings_yaml(proposed, comments, str(path))
        Settings.model_validate(yaml.safe_load(text) or {})  # what is written loads back
        with atomic_path(write_config) as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
        written = Path(write_config)
    return CheckResult(
        path=Path(path), format=fmt, ready=ready, reason=reason,
        time_base=_time_base(log.metadata), streams=streams, missing=_missing(log),
        problems=problems, proposed_topics={s: c.to_dict() for s, c in guess.items()},
        settings=proposed, warnings=tuple(dict.fromkeys(caught)), written=written,
    )  # fmt: skip
