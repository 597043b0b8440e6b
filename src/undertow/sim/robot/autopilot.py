"""A virtual ArduSub autopilot that consumes external navigation as ArduSub 4.x's EKF3 does,
so that what ``undertow live --autopilot`` sends can be checked without a vehicle.

:class:`VirtualAutopilot` is a state machine on an explicit clock (s since boot; ``undertow
serve`` drives it with the playback clock): :meth:`~VirtualAutopilot.handle` takes a pymavlink
message and returns the replies, :meth:`~VirtualAutopilot.poll` the messages due. It follows
ArduPilot's source (github.com/ArduPilot/ardupilot):

- external navigation: ODOMETRY, VISION_POSITION_ESTIMATE, VISION_POSITION_DELTA with the rules
  of :mod:`~undertow.sim.robot.autopilot_rules` (frame pair, covariance reduction and floors,
  quality, reset_counter, 20 ms / 50 ms spacing) and the aiding logic of
  :mod:`~undertow.sim.robot.autopilot_nav`; nothing is used while VISO_TYPE was 0 at boot;
- the EKF origin (``libraries/GCS_MAVLink/GCS_Common.cpp`` handle_set_gps_global_origin,
  set_ekf_origin; ``AP_NavEKF3_Control.cpp`` setOrigin): accepted once per boot, only once the
  EKF runs, replied with GPS_GLOBAL_ORIGIN and "EKF3 IMU0 origin set"; a later one is ignored
  silently;
- parameters (``GCS_Param.cpp``): PARAM_REQUEST_READ (by name or index), PARAM_REQUEST_LIST
  and PARAM_SET answered with PARAM_VALUE (index 65535 for a read or set by name, as the SITL
  does); a parameter whose docs say ``@RebootRequired`` keeps its boot value until
  MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (param1 1), after which the autopilot is silent for
  ``timing.reboot_s`` and boots again with the stored values (origin and filter reset);
  external navigation is only possible after a boot with some EK3_SRCn_ set to 6
  (``AP_NavEKF3_core.cpp`` setup_core allocates its buffers then);
- MAV_CMD_SET_MESSAGE_INTERVAL and MAV_CMD_REQUEST_MESSAGE for EKF_STATUS_REPORT (193),
  LOCAL_POSITION_NED (32) and GPS_GLOBAL_ORIGIN (49); by default only EKF_STATUS_REPORT is
  streamed (1 Hz), LOCAL_POSITION_NED must be asked for.

What is not EKF3's: the filter (a constant-velocity stand-in, :mod:`autopilot_nav`), the
height (the log's pressure as ArduSub's baro depth, d = (p - p0) / (1000 g), or 0 without one;
EK3_SRC1_POSZ 6 takes the external z), the times to start (:class:`AutopilotTiming`, from the
SITL), VISO_ORIENT and VISO_POS_* (not applied), and yaw fusion (angErr is checked and recorded,
not fused). Every message handled is counted in :attr:`VirtualAutopilot.counts` as
``"MESSAGE:outcome"`` (e.g. ``ODOMETRY:frame`` for a wrong frame pair).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from ...errors import ConfigError
from .autopilot_nav import AID_ABSOLUTE, ExtNavSample, NavFilter
from .autopilot_rules import (
    BODY_ODOM_INTERVAL_MIN_S,
    COVARIANCE_RULES,
    EXTNAV_INTERVAL_MIN_S,
    FRAME_BODY_FRD,
    FRAME_LOCAL_FRD,
    PARAMS,
    SOURCE_EXTNAV,
    body_odometry_error,
    clamp_errors,
    param_value,
    quaternion_rotate,
    reduce_covariance,
    valid_origin,
)

MSG_EKF_STATUS_REPORT = 193
MSG_LOCAL_POSITION_NED = 32
MSG_GPS_GLOBAL_ORIGIN = 49
CMD_REBOOT = 246
CMD_SET_MESSAGE_INTERVAL = 511
CMD_REQUEST_MESSAGE = 512
RESULT_ACCEPTED, RESULT_FAILED, RESULT_UNSUPPORTED = 0, 4, 3
SEVERITY_WARNING, SEVERITY_INFO = 4, 6
#: EKF3's average filter step (EKF_TARGET_DT), s: shorter body-odometry deltas are dropped
EKF_DT_S = 0.012


@dataclass(frozen=True)
class AutopilotTiming:
    """When the virtual EKF gets going (s), as the SITL does after a boot: EKF3 initialised
    ``ekf_start_s`` after boot (the origin is refused before), tilt aligned ``tilt_align_s``
    later (external navigation refused before), gyro biases learned ``bias_learn_s`` after that
    (body odometry refused before; the SITL started relative aiding about 37 s after boot);
    silent for ``reboot_s`` after a reboot command."""

    ekf_start_s: float = 3.5
    tilt_align_s: float = 1.5
    bias_learn_s: float = 30.0
    reboot_s: float = 1.0


def load_param_file(path: str | Path) -> dict[str, float]:
    """Parameters from an ArduPilot parameter file (``NAME VALUE`` or ``NAME,VALUE`` per line,
    ``#`` comments: the format of ``sub.parm`` and Mission Planner / MAVProxy saves)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"--autopilot-params {path}: cannot read ({exc})") from None
    out: dict[str, float] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        try:
            value = float(parts[1]) if len(parts) == 2 else math.nan
        except ValueError:
            value = math.nan
        if len(parts) != 2 or not math.isfinite(value) or len(parts[0]) > 16:
            raise ConfigError(f"{path}:{number}: expected 'NAME VALUE', got {raw.strip()!r}")
        out[parts[0].upper()] = value
    return out


def _text(value) -> str:
    if isinstance(value, bytes | bytearray):
        value = value.decode("ascii", "replace")
    return str(value).split("\x00", 1)[0]


class VirtualAutopilot:
    """The virtual autopilot (module docstring). ``params``: values preset as if set and
    rebooted before; ``origin``: (lat deg, lon deg, alt m) set as soon as the EKF runs, on
    every boot (an origin already on the vehicle); ``covariance``: the reduction rule
    (:data:`~undertow.sim.robot.autopilot_rules.COVARIANCE_RULES`); ``attitude(t)``: roll,
    pitch, yaw (rad) of the vehicle (body odometry is rotated with it; default level, north);
    ``depth(t)``: the baro depth (m, default 0); ``now``: the boot time."""

    def __init__(
        self,
        params: Mapping[str, float] | None = None,
        origin: tuple[float, ...] | None = None,
        *,
        covariance: str = "cbrt",
        timing: AutopilotTiming | None = None,
        attitude: Callable[[float], tuple[float, float, float]] | None = None,
        depth: Callable[[float], float] | None = None,
        now: float = 0.0,
        system: int = 1,
        component: int = 1,
    ) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        if covariance not in COVARIANCE_RULES:
            raise ConfigError(
                f"--autopilot-covariance: expected one of {', '.join(COVARIANCE_RULES)}, "
                f"got {covariance!r}"
            )
        self.m = mavlink2
        self.covariance = covariance
        self.timing = timing or AutopilotTiming()
        self.attitude = attitude
        self.depth = depth
        self.system, self.component = int(system), int(component)
        self.types = {name: spec.mav_type for name, spec in PARAMS.items()}
        self.stored = {name: spec.default for name, spec in PARAMS.items()}
        for name, value in (params or {}).items():
            name = str(name).upper()
            self.stored[name] = param_value(self.types.setdefault(name, 9), float(value))
        self.origin_preset = _origin_tuple(origin) if origin is not None else None
        self.counts: Counter[str] = Counter()
        self.boots = 0
        self._boot(float(now))

    # boot and clock -----------------------------------------------------------------------
    def _boot(self, now: float) -> None:
        self.boot_time = now
        self.boots += 1
        self.active = dict(self.stored)
        self.origin: tuple[int, int, int] | None = None
        self.texts: list[str] = []
        self._severities: list[int] = []
        configured = any(
            self.active.get(f"EK3_SRC{n}_{k}", 0) == SOURCE_EXTNAV
            for n in (1, 2, 3)
            for k in ("POSXY", "VELXY", "POSZ", "VELZ", "YAW")
        )
        self.nav = NavFilter(self.param, configured, self.texts)
        self.intervals = {MSG_EKF_STATUS_REPORT: 1.0}
        self.next_due: dict[int, float] = {}
        # AP_VisualOdom_Backend get_reset_timestamp_ms and EKF3's extNavLastPosResetTime_ms
        self.last_reset_counter = 0
        self.reset_time = self.ekf_reset_time = 0.0
        self.last_extnav_t = self.last_extvel_t = self.last_body_t = -math.inf
        self.param_queue: list[str] = []
        self.down_until = -math.inf
        self._pending_reboot: float | None = None
        self.last_sample: ExtNavSample | None = None
        self.texts.append("ArduSub virtual autopilot (EKF3 rules)")

    def param(self, name: str) -> float:
        """The value in use: the boot value of a reboot-required parameter, else the stored."""
        spec = PARAMS.get(name)
        source = self.active if spec is not None and spec.reboot else self.stored
        return source.get(name, spec.default if spec else 0.0)

    def boot_ms(self, now: float) -> int:
        return int(min(max(round((now - self.boot_time) * 1e3), 0), 2**32 - 1))

    def _ekf_enabled(self) -> bool:
        return self.active.get("EK3_ENABLE", 1) != 0 and self.param("AHRS_EKF_TYPE") == 3

    def _step(self, now: float) -> None:
        """Boot milestones and timeouts up to ``now``."""
        if self._pending_reboot is not None and now >= self._pending_reboot:
            self._pending_reboot = None
            self._boot(self.down_until)
        since = now - self.boot_time
        t = self.timing
        nav = self.nav
        if self._ekf_enabled() and not nav.initialised and since >= t.ekf_start_s:
            nav.initialised = True
            nav.t = now
            self.texts += ["EKF3 IMU0 initialised", "AHRS: EKF3 active"]
            if self.origin_preset is not None:
                self._set_origin(*self.origin_preset)
        if nav.initialised and not nav.tilt_aligned and since >= t.ekf_start_s + t.tilt_align_s:
            nav.tilt_aligned = True
            self.texts.append("EKF3 IMU0 tilt alignment complete")
        if nav.tilt_aligned and since >= t.ekf_start_s + t.tilt_align_s + t.bias_learn_s:
            nav.bias_learned = True
        if self.depth is not None and int(self.param("EK3_SRC1_POSZ")) != SOURCE_EXTNAV:
            nav.z = float(self.depth(now))
        nav.advance(now)

    @property
    def down(self) -> bool:
        return self._pending_reboot is not None

    # messages in --------------------------------------------------------------------------
    def handle(self, msg, now: float) -> list:
        """The replies to ``msg`` (a pymavlink message) received at ``now``."""
        now = float(now)
        self._step(now)
        kind = msg.get_type()
        if self.down:
            self.counts[f"{kind}:rebooting"] += 1
            return []
        handler = {
            "ODOMETRY": self._odometry,
            "VISION_POSITION_ESTIMATE": self._vision_position,
            "VISION_POSITION_DELTA": self._vision_delta,
            "SET_GPS_GLOBAL_ORIGIN": self._set_origin_msg,
            "PARAM_REQUEST_READ": self._param_read,
            "PARAM_REQUEST_LIST": self._param_list,
            "PARAM_SET": self._param_set,
            "COMMAND_LONG": self._command,
            "COMMAND_INT": self._command,
        }.get(kind)
        if handler is None:
            return []
        out = handler(msg, now) or []
        return out + self._drain_texts()

    def _count(self, kind: str, outcome: str) -> str:
        self.counts[f"{kind}:{outcome}"] += 1
        return outcome

    def _odometry(self, msg, now: float) -> None:
        if msg.frame_id != FRAME_LOCAL_FRD or msg.child_frame_id != FRAME_BODY_FRD:
            self._count("ODOMETRY", "frame")  # GCS_Common.cpp handle_odometry: silent return
            return
        q = tuple(float(v) for v in msg.q)
        vel = quaternion_rotate(q, (msg.vx, msg.vy, msg.vz))
        self._pose("ODOMETRY", msg, now, q, msg.pose_covariance, int(msg.quality), vel)

    def _vision_position(self, msg, now: float) -> None:
        cov = getattr(msg, "covariance", None) or [0.0] * 21
        q = _euler_to_quaternion(msg.roll, msg.pitch, msg.yaw)
        self._pose("VISION_POSITION_ESTIMATE", msg, now, q, cov, 0, None)

    def _pose(self, kind, msg, now, q, cov, quality, vel) -> None:
        """AP_VisualOdom_MAV.cpp handle_pose_estimate and handle_vision_speed_estimate, then
        EKF3's writeExtNavData / writeExtNavVelData (autopilot_rules module docstring)."""
        if self.active.get("VISO_TYPE", 0) == 0:
            self._count(kind, "viso_disabled")
            return
        pos_err, ang_err = reduce_covariance(cov, self.covariance)
        pos_err, ang_err = clamp_errors(
            pos_err, ang_err, self.param("VISO_POS_M_NSE"), self.param("VISO_YAW_M_NSE")
        )
        if quality < self.param("VISO_QUAL_MIN"):
            self._count(kind, "quality")
            return
        if int(msg.reset_counter) != self.last_reset_counter:
            self.last_reset_counter = int(msg.reset_counter)
            self.reset_time = now
        scale = self.param("VISO_SCALE")
        pos = (float(msg.x) * scale, float(msg.y) * scale, float(msg.z) * scale)
        if not self.nav.initialised or not self._ekf_enabled():
            self._count(kind, "ekf_not_ready")
            return
        if any(math.isnan(v) for v in pos) or math.isnan(pos_err):
            self._count(kind, "nan")
        elif now - self.last_extnav_t < EXTNAV_INTERVAL_MIN_S:
            self._count(kind, "rate")
        else:
            self.last_extnav_t = now
            reset = self.reset_time != self.ekf_reset_time
            self.ekf_reset_time = self.reset_time
            sample = ExtNavSample(pos, pos_err, ang_err, now, reset)
            self.last_sample = sample
            self._count(kind, self.nav.extnav_position(sample, self._ext_vel(vel, now)))
        if vel is not None and now - self.last_extvel_t >= EXTNAV_INTERVAL_MIN_S:
            if not any(math.isnan(v) for v in vel):
                self.last_extvel_t = now
                if self.nav.extnav_velocity(vel, self.param("VISO_VEL_M_NSE"), now):
                    self.counts[f"{kind}:velocity_fused"] += 1

    def _ext_vel(self, vel, now: float):
        usable = vel is not None and not any(math.isnan(v) for v in vel)
        return vel if usable and now - self.last_extvel_t >= EXTNAV_INTERVAL_MIN_S else None

    def _vision_delta(self, msg, now: float) -> None:
        """AP_VisualOdom_Backend.cpp handle_vision_position_delta_msg and EKF3's
        writeBodyFrameOdom: v_body = position_delta / dt, velErr from confidence."""
        kind = "VISION_POSITION_DELTA"
        if self.active.get("VISO_TYPE", 0) == 0:
            self._count(kind, "viso_disabled")
            return
        dt = float(msg.time_delta_usec) * 1e-6
        values = [*msg.position_delta, *msg.angle_delta, float(msg.confidence), dt]
        if any(math.isnan(float(v)) for v in values):
            self._count(kind, "nan")
        elif not self.nav.initialised or not self._ekf_enabled():
            self._count(kind, "ekf_not_ready")
        elif now - self.last_body_t < BODY_ODOM_INTERVAL_MIN_S or dt < EKF_DT_S:
            self._count(kind, "rate")
        else:
            self.last_body_t = now
            v_body = [float(d) / dt for d in msg.position_delta]
            err = body_odometry_error(
                msg.confidence, self.param("EK3_VIS_VERR_MIN"), self.param("EK3_VIS_VERR_MAX")
            )
            rpy = self.attitude(now) if self.attitude is not None else (0.0, 0.0, 0.0)
            v_ned = quaternion_rotate(_euler_to_quaternion(*rpy), v_body)
            delay = self.param("VISO_DELAY_MS") * 1e-3
            self._count(kind, self.nav.body_odometry(v_ned, err, now, delay))

    def _set_origin_msg(self, msg, now: float) -> list:
        if int(getattr(msg, "target_system", 0)) not in (0, self.system):
            return []
        lat, lon, alt = int(msg.latitude), int(msg.longitude), int(msg.altitude)
        if not valid_origin(lat, lon, alt):
            self._count("SET_GPS_GLOBAL_ORIGIN", "invalid")
            return []
        if not self.nav.initialised:
            self._count("SET_GPS_GLOBAL_ORIGIN", "ekf_not_ready")
            return []
        if self.origin is not None:
            self._count("SET_GPS_GLOBAL_ORIGIN", "already_set")
            return []
        self._count("SET_GPS_GLOBAL_ORIGIN", "set")
        return [self._set_origin(lat, lon, alt, now)]

    def _set_origin(self, lat: int, lon: int, alt_mm: int, now: float | None = None):
        self.origin = (int(lat), int(lon), int(alt_mm))
        self.texts.append("EKF3 IMU0 origin set")
        return self._origin_message(self.boot_time if now is None else now)

    def _origin_message(self, now: float):
        lat, lon, alt = self.origin
        return self.m.MAVLink_gps_global_origin_message(lat, lon, alt, self.boot_ms(now) * 1000)

    # parameters ---------------------------------------------------------------------------
    def _names(self) -> list[str]:
        return sorted(self.stored)

    def _param_message(self, name: str, index: int = 65535):
        return self.m.MAVLink_param_value_message(
            name.encode(), float(self.stored[name]), self.types[name], len(self.stored), index
        )

    def _targets_us(self, msg) -> bool:
        return int(getattr(msg, "target_system", 0)) in (0, self.system)

    def _param_read(self, msg, now: float) -> list:
        if not self._targets_us(msg):
            return []
        name = _text(msg.param_id).upper()
        if int(msg.param_index) >= 0:
            names = self._names()
            if int(msg.param_index) >= len(names):
                return []
            name = names[int(msg.param_index)]
            return [self._param_message(name, int(msg.param_index))]
        if name not in self.stored:
            self._count("PARAM_REQUEST_READ", "unknown")
            return []
        return [self._param_message(name)]

    def _param_list(self, msg, now: float) -> list:
        if self._targets_us(msg):
            self.param_queue = self._names()
        return []

    def _param_set(self, msg, now: float) -> list:
        if not self._targets_us(msg):
            return []
        name = _text(msg.param_id).upper()
        if name not in self.stored or not math.isfinite(float(msg.param_value)):
            self._count("PARAM_SET", "unknown")
            return []
        self.stored[name] = param_value(self.types[name], float(msg.param_value))
        spec = PARAMS.get(name)
        self._count("PARAM_SET", "needs_reboot" if spec is not None and spec.reboot else "set")
        return [self._param_message(name)]

    # commands -----------------------------------------------------------------------------
    def _command(self, msg, now: float) -> list:
        if not self._targets_us(msg):
            return []
        cmd = int(msg.command)
        result = RESULT_UNSUPPORTED
        out = []
        if cmd == CMD_REBOOT:
            if int(getattr(msg, "target_component", 0)) not in (0, self.component):
                result = 2  # MAV_RESULT_DENIED
            elif msg.param1 in (1.0, 3.0):
                result = RESULT_ACCEPTED
                self.down_until = now + self.timing.reboot_s
            self._count("COMMAND", f"reboot_{result}")
        elif cmd == CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(int(msg.param1), float(msg.param2))
        elif cmd == CMD_REQUEST_MESSAGE:
            reply = self._message(int(msg.param1), now)
            result = RESULT_ACCEPTED if reply is not None else RESULT_FAILED
            out = [reply] if reply is not None else []
        ack = self.m.MAVLink_command_ack_message(
            cmd, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
        )
        if cmd == CMD_REBOOT and result == RESULT_ACCEPTED:
            self._pending_reboot = self.down_until
        return [ack, *out]

    def _set_interval(self, msg_id: int, interval_us: float) -> int:
        """GCS_Common.cpp set_message_interval: 0 the default, -1 stop, else the interval (us,
        at least 1 ms, at most 60 s)."""
        if msg_id not in (MSG_EKF_STATUS_REPORT, MSG_LOCAL_POSITION_NED, MSG_GPS_GLOBAL_ORIGIN):
            return RESULT_FAILED
        if interval_us == 0:
            default = {MSG_EKF_STATUS_REPORT: 1.0}.get(msg_id)
            self.intervals.pop(msg_id, None)
            if default:
                self.intervals[msg_id] = default
        elif interval_us == -1:
            self.intervals.pop(msg_id, None)
        elif interval_us < 0:
            return 2
        else:
            self.intervals[msg_id] = min(max(interval_us * 1e-6, 1e-3), 60.0)
        self.next_due.pop(msg_id, None)
        return RESULT_ACCEPTED

    # messages out -------------------------------------------------------------------------
    def _message(self, msg_id: int, now: float):
        if msg_id == MSG_GPS_GLOBAL_ORIGIN:
            return self._origin_message(now) if self.origin is not None else None
        if msg_id == MSG_EKF_STATUS_REPORT:
            ratio = math.sqrt(max(self.nav.pos_test_ratio, 0.0))
            return self.m.MAVLink_ekf_status_report_message(
                self.nav.flags(), 0.0, ratio, 0.0, 0.0, 0.0, 0.0
            )
        if msg_id == MSG_LOCAL_POSITION_NED:
            pos = self.nav.position() if self._ekf_enabled() else None
            if pos is None:
                return None
            vel = self.nav.velocity()
            return self.m.MAVLink_local_position_ned_message(self.boot_ms(now), *pos, *vel)
        return None

    def _drain_texts(self) -> list:
        out = []
        for text in self.texts:
            severity = SEVERITY_WARNING if "stopped aiding" in text else SEVERITY_INFO
            out.append(self.m.MAVLink_statustext_message(severity, text.encode()[:50], 0, 0))
        self.texts.clear()
        return out

    def poll(self, now: float) -> list:
        """The messages due at ``now``: STATUSTEXTs, the streams, queued PARAM_VALUEs."""
        now = float(now)
        self._step(now)
        if self.down:
            return []
        out = self._drain_texts()
        for msg_id, interval in sorted(self.intervals.items()):
            due = self.next_due.get(msg_id, now)
            if now >= due:
                reply = self._message(msg_id, now)
                if reply is not None:
                    out.append(reply)
                self.next_due[msg_id] = max(due + interval, now)
        names = self._names()
        for name in self.param_queue[:20]:
            out.append(self._param_message(name, names.index(name)))
        del self.param_queue[:20]
        return out

    # state --------------------------------------------------------------------------------
    @property
    def using_external_nav(self) -> bool:
        """EKF3 is fusing the external position now (EKF_POS_HORIZ_ABS set)."""
        return self.nav.mode == AID_ABSOLUTE and not self.nav.pos_timeout

    def summary(self) -> dict:
        """What was accepted and why not (counts), the aiding mode, flags, origin, position."""
        pos = self.nav.position()
        return {
            "counts": dict(sorted(self.counts.items())),
            "aiding": self.nav.mode,
            "flags": self.nav.flags(),
            "origin": list(self.origin) if self.origin else None,
            "position_ned_m": list(pos) if pos else None,
            "boots": self.boots,
            "covariance_rule": self.covariance,
        }


def _origin_tuple(origin) -> tuple[int, int, int]:
    values = [float(v) for v in origin]
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--autopilot-origin: expected LAT,LON[,ALT], got {origin!r}")
    lat, lon, alt = (values + [0.0])[:3]
    out = (int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1e3)))
    if not valid_origin(*out):
        raise ConfigError(f"--autopilot-origin: {lat}, {lon}, {alt} is not a valid location")
    return out


def _euler_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """(w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll) (ArduPilot's Quaternion::from_euler)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )
