"""The sea state from the robot's own sensors (barometer, DVL, orientation): no wave probe.

Per window of about 20 wave periods, one regular linear wave (amplitude a, intrinsic angular
frequency omega, propagation direction beta) is fitted coherently to every channel at once,
through the transfer functions of :mod:`undertow.sim.waves` (Dean & Dalrymple,
"Water Wave Mechanics for Engineers and Scientists", 1991, ch. 3-4; the encounter-frequency
and pressure/velocity "PUV" ideas of wave gauging from moving and fixed instruments, e.g.
Lewis, "Principles of Naval Architecture" vol. III, SNAME 1989, and Tucker & Pitt, "Waves in
Ocean Engineering", Elsevier 2001, ch. 6).

Inputs: the barometer's pressure head (p - p_atm) / (rho g); the DVL velocity rotated to the body
(mount rotation), less the lever-arm velocity omega_b x r_dvl (gyro), then to the world frame
by the orientation (dead reckoning's attitude, else the IMU's orientation, else the gyro's yaw
rate integrated, else none: body frame). Water depth h = median(barometer depth + lever +
DVL altitude), else the caller's or the log's "water_depth_m", else deep water.

Phase model along the dead-reckoned track (x(t), y(t)) of the window (the world velocity
smoothed over one encounter period and integrated):

    theta(t) = k (x(t) cos beta + y(t) sin beta) - omega t + phi,   omega^2 = g k tanh(k h)

Channels (high-passed, x - MA(MA(x)) over one encounter period, to remove the vehicle's own slow
motion; the final fit applies the same filter to the model), with c = a e^{i phi} and
omega_e(t) = omega - k V(t) . e_beta the encounter frequency, d the body depth:

    rigid:  head(t)  = a K_p(d) cos theta                  (barometer, pressure head in m)
    free:   head(t)  = a (K_p(d) - K_s(d)) cos theta
            u(t)     = a K_h(d) omega_e(t) cos theta e_beta     (DVL velocity over the floor)
            w_dn(t)  = -a K_s(d) omega_e(t) sin theta

Each model is linear in (Re c, Im c) for a given (omega, beta), so the maximum-likelihood fit
(Gaussian noise of unknown variance per channel) is a weighted least squares for c inside a
search over (omega, beta): candidates from the encounter-frequency periodogram peaks
(zero-padded, parabolic interpolation; each peak with each distinct velocity of the window, on
the ridge omega - k V . e_beta = omega_e), directions from a 30 deg grid (rigid) or the
principal axis of the horizontal orbital velocity (free, the PUV direction, both senses), then a
zoom on halving 3 x 3 grids (compiled); the channel weights 1/sigma_c^2 are re-estimated from
the residuals. The platform (rigid or free) with the larger profile likelihood
-1/2 sum_c n_c log(RSS_c / n_c) is kept ("auto" tries the free model when the DVL shows the
encounter peak). H_m0 = 4 sqrt(m0) = 2 sqrt(2) a for a regular wave. A window is calm when the
wave's chi-square improvement sum_c (TSS_c - RSS_c) / sigma_c^2 does not exceed 2 ln(M / alpha),
the level a maximum over the M independent frequency and direction cells reaches in noise alone
(alpha = 1e-3), or the wave explains less than 15 % of the weighted variance.

Direction. The free vehicle's orbital velocity gives beta (its axis, and the sense from the
phase of the vertical motion and the Doppler shift). A rigid mount sees beta only through the
track, and only when speed or heading vary in the window (at constant velocity only omega_e is
observable): on a curved track it is tested on the profile likelihood over beta; on a straight
track only c = cos(beta - course) enters, fitted in [-1.3, 1.3] (not clipped to +-1, which would
push a head-sea c = -1 inward and bias omega up) and pooled (median) over the nearest windows
where the speed changes. A window whose direction is not observable borrows it from the nearest
window where it was (and says so), else reports the encounter frequency as the intrinsic one
(at rest exact; moving: beam seas assumed). The vehicle is assumed slower than the waves
(omega_e > 0, the rising branch of omega - k U).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..errors import ConfigError, DataError
from ..log import FRESH_WATER_DENSITY, G0, P_ATM, Log
from ..rotations import quaternion_to_rpy, rpy_to_matrix, wrap_angle
from ..sim.waves import intrinsic_from_encounter, wavenumber, wavenumber_array
from ..wavetrack import WaveTrack

PLATFORMS = ("auto", "rigid", "free")
F_LOW_HZ = 0.2  # lowest encounter frequency searched (periods up to 5 s)
_BETAS = np.deg2rad(np.arange(0.0, 360.0, 15.0))
_ALPHA = 1e-3
MIN_VELOCITY_PEAK = 100.0  # auto: the free model is tried when the DVL shows the encounter peak
MIN_EXPLAINED = 0.15  # a regular wave explaining less of the high-passed variance is not one
POOL_WINDOWS = 4  # straight rigid tracks: informed windows pooled on each side
_CONSENSUS_LOGLIK = 10.0  # log-likelihood a neighbours' direction may cost (module doc)
_CLEAR_LOGLIK = 50.0  # free over rigid-at-its-direction: no full rigid search needed
_DIR_CHI2 = 10.8  # chi-square(1) at 99.9 %: a direction is rejected above this


@dataclass(frozen=True)
class WaveWindow:
    """The wave condition fitted in one window (amplitude 0 and frequencies None when calm)."""

    t_start: float
    t_end: float
    amplitude_m: float
    frequency_hz: float | None
    encounter_frequency_hz: float | None
    significant_height_m: float
    direction_deg: float | None
    relative_direction_deg: float | None
    platform: str
    sensors: tuple[str, ...]
    explained: float
    notes: tuple[str, ...] = ()

    @property
    def calm(self) -> bool:
        return self.amplitude_m == 0.0

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["sensors"], out["notes"] = list(self.sensors), list(self.notes)
        return out


@dataclass(frozen=True)
class SeaStateEstimate:
    """Windows of the estimate, the window length and step (s), and notes on the whole log."""

    windows: list[WaveWindow]
    window_s: float
    step_s: float
    notes: list[str] = field(default_factory=list)

    def track(self) -> WaveTrack:
        """The estimate as a :class:`WaveTrack` (source "estimated"), one node per window
        centre."""
        w = self.windows
        nan = float("nan")
        return WaveTrack(
            np.array([0.5 * (x.t_start + x.t_end) for x in w]),
            np.array([x.amplitude_m for x in w]),
            np.array([nan if x.frequency_hz is None else x.frequency_hz for x in w]),
            source="estimated",
            direction_deg=np.array(
                [nan if x.direction_deg is None else x.direction_deg for x in w]
            ),
        )

    def to_dict(self) -> dict:
        return {
            "window_s": self.window_s,
            "step_s": self.step_s,
            "notes": list(self.notes),
            "windows": [w.to_dict() for w in self.windows],
        }

    def to_table_rows(self) -> list[dict]:
        """One plain row per window for a table (None where unknown)."""

        def r(v, n):
            return None if v is None else round(float(v), n)

        return [
            {
                "t_start_s": r(w.t_start, 2), "t_end_s": r(w.t_end, 2),
                "amplitude_m": r(w.amplitude_m, 4), "frequency_hz": r(w.frequency_hz, 4),
                "encounter_hz": r(w.encounter_frequency_hz, 4),
                "hm0_m": r(w.significant_height_m, 4), "direction_deg": r(w.direction_deg, 1),
                "relative_deg": r(w.relative_direction_deg, 1), "platform": w.platform,
                "explained": r(w.explained, 3), "sensors": ",".join(w.sensors),
            }
            for w in self.windows
        ]  # fmt: skip


# ----------------------------------------------------------------------------- data preparation


@dataclass
class _Channel:
    name: str
    kind: str  # "p", "vx", "vy", "vz"
    t: np.ndarray
    y: np.ndarray
    depth: float
    rate: float
    x: np.ndarray | None = None  # track at t (None: no track)
    yy: np.ndarray | None = None
    vx: np.ndarray | None = None  # slow velocity over ground at t
    vy: np.ndarray | None = None


@dataclass
class _Data:
    channels: list[_Channel]
    sensors: tuple[str, ...]
    h: float
    frame: str | None  # "world", "relative" (heading integrated from the gyro), "body", None
    heading: tuple[np.ndarray, np.ndarray] | None
    vel: tuple[np.ndarray, np.ndarray] | None  # (t, world velocity (N, 3))
    notes: list[str]
    g: float = G0


def _check_options(platform, window_periods, step_fraction, water_depth_m, rho, t_start, t_end):
    if platform not in PLATFORMS:
        raise ConfigError(f"platform {platform!r}: expected one of {', '.join(PLATFORMS)}")
    for name, value, positive in (
        ("window_periods", window_periods, True), ("step_fraction", step_fraction, True),
        ("water_depth_m", water_depth_m, True), ("water_density_kg_m3", rho, True),
        ("t_start", t_start, False), ("t_end", t_end, False),
    ):  # fmt: skip
        if value is None and name not in ("window_periods", "step_fraction"):
            continue
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{name} {value!r:.40}: not a number") from None
        if not math.isfinite(v) or (positive and v <= 0):
            raise ConfigError(f"{name} {value!r:.40}: must be a finite number" + (
                " > 0" if positive else ""))  # fmt: skip
    if float(step_fraction) > 1.0 or float(window_periods) < 3.0:
        raise ConfigError(
            "step_fraction must be in (0, 1] and window_periods at least 3 "
            f"(got {step_fraction}, {window_periods})"
        )


def _crop(log: Log, t_start, t_end) -> Log:
    if t_start is None and t_end is None:
        return log
    lo = -np.inf if t_start is None else float(t_start)
    hi = np.inf if t_end is None else float(t_end)
    changes = {n: s.select((s.t >= lo) & (s.t <= hi)) for n, s in log.streams().items()}
    return log.replace(**changes)


def _orientation(log: Log, t: np.ndarray, notes: list[str]):
    """(R world-from-body (N, 3, 3), yaw (N,), frame) at ``t`` from the dead reckoning's
    attitude, else the IMU's orientation, else the gyro's yaw rate integrated (relative to the
    first heading), else the body frame (identity)."""
    dr, imu = log.dead_reckoning, log.imu
    if dr is not None and len(dr) >= 2 and np.isfinite(dr.orientation).all():
        rpy = np.unwrap(dr.orientation, axis=0)
        rpy = np.stack([np.interp(t, dr.t, rpy[:, i]) for i in range(3)], axis=1)
        return rpy_to_matrix(rpy), rpy[:, 2], "world"
    if imu is not None and len(imu) >= 2:
        if imu.orientation is not None and np.isfinite(imu.orientation).all():
            rpy = np.unwrap(quaternion_to_rpy(imu.orientation), axis=0)
            rpy = np.stack([np.interp(t, imu.t, rpy[:, i]) for i in range(3)], axis=1)
            return rpy_to_matrix(rpy), rpy[:, 2], "world"
        r = np.nan_to_num(imu.angular_velocity[:, 2])
        yaw = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(imu.t))])
        notes.append("orientation: yaw integrated from the gyro (small roll and pitch assumed); "
                     "directions relative to the first heading")  # fmt: skip
        yaw = np.interp(t, imu.t, yaw)
        rpy = np.stack([np.zeros_like(t), np.zeros_like(t), yaw], axis=1)
        return rpy_to_matrix(rpy), yaw, "relative"
    notes.append("no orientation: DVL velocities in the body frame, directions relative to "
                 "the vehicle only")  # fmt: skip
    return np.broadcast_to(np.eye(3), (t.size, 3, 3)), np.zeros_like(t), "body"


def _depths(log: Log, rho: float, water_depth_m, notes: list[str]):
    """(barometer depth d_p, body depth d_b, water depth h); NaN where unknown, h = inf for
    deep water. h = median(d_p + lever + altitude) with both sensors; the body depth (where a
    free vehicle is displaced by the orbit as a whole) is d_p minus the barometer's lever arm."""
    p, dvl = log.pressure, log.dvl
    surface = float(log.metadata.get("surface_pressure_pa", P_ATM) or P_ATM)
    d_p = float(np.nanmedian(p.depth(rho, surface))) if p is not None and len(p) else np.nan
    z_baro, z_dvl = log.mounting.barometer.translation[2], log.mounting.dvl.translation[2]
    alt = np.nan
    if dvl is not None and np.isfinite(dvl.altitude).any():
        alt = float(np.nanmedian(dvl.altitude))
    h = np.nan
    if water_depth_m is not None:
        h = float(water_depth_m)
    elif np.isfinite(d_p) and np.isfinite(alt):
        h = d_p - z_baro + z_dvl + alt
    elif _finite(log.metadata.get("water_depth_m")):
        h = float(log.metadata["water_depth_m"])
    if not np.isfinite(h):
        h = np.inf
        notes.append("water depth unknown: deep water assumed")
    d_b = d_p - z_baro if np.isfinite(d_p) else h - alt - z_dvl
    if not np.isfinite(d_b) and dvl is not None:
        d_b = 0.0
        notes.append("vehicle depth unknown (no barometer, no water depth): taken at the "
                     "surface, so the amplitude is a lower bound")  # fmt: skip
    return d_p, d_b, h


def _finite(v) -> bool:
    try:
        return math.isfinite(float(v)) and float(v) > 0
    except (TypeError, ValueError):
        return False


def _lever_velocity(log: Log, t: np.ndarray) -> np.ndarray:
    """omega_b x r_dvl (N, 3): the DVL point's velocity from the body's rotation (gyro rates
    interpolated at ``t``), subtracted so the velocity is the body origin's; zero without an
    IMU."""
    imu = log.imu
    if imu is None or len(imu) < 2:
        return np.zeros((t.size, 3))
    w_i = np.nan_to_num(imu.angular_velocity) @ log.mounting.imu.rotation_matrix().T
    w = np.stack([np.interp(t, imu.t, w_i[:, i]) for i in range(3)], axis=1)
    return np.cross(w, np.asarray(log.mounting.dvl.translation, float))


def _prepare(log: Log, rho: float, water_depth_m) -> _Data:
    notes: list[str] = []
    d_p, d_b, h = _depths(log, rho, water_depth_m, notes)
    chans, sensors, frame, heading, vel = [], [], None, None, None
    p = log.pressure
    if p is not None and len(p) > 8:
        ok = np.isfinite(p.pressure)
        pr = p.select(ok)
        head = (pr.pressure - float(log.metadata.get("surface_pressure_pa", P_ATM) or P_ATM)) / (
            rho * G0
        )
        chans.append(_Channel("pressure", "p", pr.t, head, d_p, pr.rate_hz))
        sensors.append("pressure")
    dvl = log.dvl
    if dvl is not None and len(dvl) > 8:
        ok = dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
        d = dvl.select(ok)
        if len(d) > 8:
            R, yaw, frame = _orientation(log, d.t, notes)
            v_b = d.velocity @ log.mounting.dvl.rotation_matrix().T - _lever_velocity(log, d.t)
            v = np.einsum("nij,nj->ni", R, v_b)
            vel, heading = (d.t, v), (d.t, yaw)
            for i, kind in enumerate(("vx", "vy", "vz")):
                chans.append(_Channel("dvl", kind, d.t, v[:, i], d_b, d.rate_hz))
            sensors.append("dvl")
            if frame == "world":
                sensors.append("dead_reckoning" if log.dead_reckoning is not None else "imu")
            elif frame == "relative":
                sensors.append("imu")
    if not chans:
        raise DataError(
            "sea-state estimate needs stream pressure (barometer) or dvl (with valid "
            f"velocities); the log has: {', '.join(log.streams()) or 'none'}"
        )
    return _Data(chans, tuple(sensors), h, frame, heading, vel, notes)


def _attach_track(data: _Data, smooth_s: float) -> None:
    """Track (x, y) and slow velocity at every channel's times: the world velocity smoothed over
    ``smooth_s`` (one encounter period: the orbital part averages out) and integrated."""
    if data.vel is None:
        return
    t, v = data.vel
    n = max(int(round(smooth_s * len(t) / max(t[-1] - t[0], 1e-9))), 1)
    vs = _ma(_ma(v[:, :2].T, n), n)
    xy = np.concatenate([np.zeros((2, 1)), np.cumsum(0.5 * (vs[:, 1:] + vs[:, :-1]) * np.diff(t),
                                                      axis=1)], axis=1)  # fmt: skip
    for c in data.channels:
        c.x, c.yy = np.interp(c.t, t, xy[0]), np.interp(c.t, t, xy[1])
        c.vx, c.vy = np.interp(c.t, t, vs[0]), np.interp(c.t, t, vs[1])


# ------------------------------------------------------------------------------ signal helpers


def _ma(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average of n samples along the last axis (shrinking at the ends)."""
    m = x.shape[-1]
    n = int(max(1, min(n, m)))
    cs = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum(x, axis=-1)], axis=-1)
    i = np.arange(m)
    lo = np.clip(i - n // 2, 0, m)
    hi = np.clip(i - n // 2 + n, 0, m)
    return (cs[..., hi] - cs[..., lo]) / (hi - lo)


def _highpass(x: np.ndarray, n: int) -> np.ndarray:
    """x - MA_n(MA_n(x)): removes the slow motion (gain 1 - sinc^2(f n dt))."""
    y = np.array(x, dtype=float)
    m = y.size
    _highpass_inplace(y, m, int(max(1, min(n, m))), np.empty(m + 1), np.empty(m))
    return y


def _spectrum_peaks(chans: list[_Channel], t0: float, t1: float, count: int = 3):
    """Encounter angular frequencies of the highest peaks of the summed, noise-normalized
    periodograms (Hann window, zero padded 2x, parabolic interpolation of log power), and the
    velocity channels' highest peak-to-median ratio near those peaks. Each periodogram is
    weighted by f (half a derivative) so the vehicle's own manoeuvres (turns, speed changes:
    slow, broadband) do not outrank the wave."""
    rate = max(c.rate for c in chans)
    nyq = 0.5 * min(c.rate for c in chans)
    tg = np.arange(t0, t1, 1.0 / rate)
    if tg.size < 16:
        return np.array([]), 0.0
    nfft = 1 << int(np.ceil(np.log2(2 * tg.size)))
    f = np.fft.rfftfreq(nfft, 1.0 / rate)
    band = (f >= F_LOW_HZ) & (f <= 0.9 * nyq)
    if band.sum() < 3:
        return np.array([]), 0.0
    win = np.hanning(tg.size)
    rows = []
    for c in chans:
        y = _highpass(c.y, int(round(c.rate / F_LOW_HZ / 2)))
        yg = np.interp(tg, c.t, y, left=0.0, right=0.0)
        rows.append((yg - yg.mean()) * win)
    spec = np.abs(np.fft.rfft(np.array(rows), nfft, axis=1)[:, band]) ** 2 * f[band]
    spec /= np.maximum(np.median(spec, axis=1, keepdims=True), 1e-300)
    total = spec.sum(axis=0)
    is_v = np.array([c.kind != "p" for c in chans])
    velocity = spec[is_v].max(axis=0) if is_v.any() else np.zeros(total.size)
    fb = f[band]
    peak = (total[1:-1] > total[:-2]) & (total[1:-1] >= total[2:])
    idx = np.nonzero(peak)[0] + 1
    idx = idx[np.argsort(total[idx])[::-1][:count]]
    lt = np.log(np.maximum(total, 1e-300))
    out = []
    for i in idx:
        den = lt[i - 1] - 2 * lt[i] + lt[i + 1]
        shift = 0.5 * (lt[i - 1] - lt[i + 1]) / den if den < 0 else 0.0
        out.append(2 * np.pi * (fb[i] + np.clip(shift, -1, 1) * (fb[1] - fb[0])))
    near = [velocity[max(i - 4, 0) : i + 5].max() for i in idx]
    return np.array(out), float(max(near, default=0.0))


# ---------------------------------------------------------------------------- the coherent fit


@dataclass
class _Window:
    chans: list[_Channel]  # sliced, t relative to the window start, data high-passed
    n_hp: list[int]
    tss: np.ndarray
    n: np.ndarray
    duration: float
    has_track: bool
    v_mean: np.ndarray  # mean slow velocity (2,)
    v_segments: list  # distinct slow velocities (mean, and at 5 times) within 0.05 m/s
    course: float  # direction of the mean velocity (rad; 0 at rest)
    straight: bool  # the track keeps within 0.1 m of a line
    h: float
    g: float
    packed: tuple = ()

    def pack(self) -> None:
        """Concatenated channel arrays for the numba kernel."""
        cat = np.concatenate

        def track(name):
            return cat([getattr(c, name) if c.x is not None else np.zeros(c.t.size)
                        for c in self.chans])  # fmt: skip

        self.packed = (
            cat([c.t for c in self.chans]),
            track("x"),
            track("yy"),
            track("vx"),
            track("vy"),
            cat([c.y for c in self.chans]),
            np.cumsum([0] + [c.t.size for c in self.chans]).astype(np.int64),
            np.array([_KINDS[c.kind] for c in self.chans], dtype=np.int64),
            np.array(self.n_hp, dtype=np.int64),
            np.array([c.depth for c in self.chans], dtype=float),
            np.array(
                [i > 0 and c.t is self.chans[i - 1].t for i, c in enumerate(self.chans)],
                dtype=np.bool_,
            ),  # fmt: skip
        )


_KINDS = {"p": 0, "vx": 1, "vy": 2, "vz": 3}
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}  # no nnan/ninf: h may be inf


@njit(cache=True, fastmath=_FAST)
def _highpass_inplace(x, n, L, cs, tmp):
    """x[:n] -= MA_L(MA_L(x[:n])) (centred moving averages shrinking at the ends)."""
    for _ in range(2):
        cs[0] = 0.0
        for i in range(n):
            cs[i + 1] = cs[i] + (x[i] if _ == 0 else tmp[i])
        for i in range(n):
            lo = max(i - L // 2, 0)
            hi = min(i - L // 2 + L, n)
            tmp[i] = (cs[hi] - cs[lo]) / (hi - lo)
    for i in range(n):
        x[i] -= tmp[i]


@njit(cache=True)
def _factors(k, h, d):
    """(K_h, K_s, K_p) as in wave_transfer.depth_factors, scalar."""
    if not np.isfinite(h):
        e = np.exp(-k * max(d, 0.0))
        return e, e, e
    d = min(max(d, 0.0), h)
    e1, e2, m = np.exp(-k * d), np.exp(-k * (2.0 * h - d)), np.exp(-2.0 * k * h)
    return (e1 + e2) / (1.0 - m), (e1 - e2) / (1.0 - m), (e1 + e2) / (1.0 + m)


@njit(cache=True, fastmath=_FAST)
def _fit_kernel(omega, ex, ey, g0, h, free, hp, T, X, Y, VX, VY, D, starts, kinds, nhp, depth,
                share, weights, tss, track):  # fmt: skip
    """For each candidate (omega_g, direction vector (ex_g, ey_g) = gain (cos beta, sin beta)),
    k_g from the dispersion relation: the regressors
    A, B of every channel the model predicts (module doc: y = Re(c) A + Im(c) B), high-passed
    like the data if ``hp`` (the search skips it: a sinusoid near the encounter frequency
    passes the filter almost unchanged), then the weighted least squares c and each channel's
    residual sum of squares."""
    G, C = omega.size, kinds.size
    k = wavenumber_array(omega, h, g0)
    chi2, cc, rss = np.empty(G), np.zeros((G, 2)), np.empty((G, C))
    nmax = int(np.max(starts[1:] - starts[:-1]))
    A, B = np.empty(nmax), np.empty(nmax)
    CO, SI, WE = np.empty(nmax), np.empty(nmax), np.empty(nmax)
    cs, tmp = np.empty(nmax + 1), np.empty(nmax)
    part = np.zeros((C, 5))
    for g in range(G):
        w, kk = omega[g], k[g]
        cb, sb = ex[g], ey[g]
        M00 = M01 = M11 = r0 = r1 = 0.0
        done = False
        for c in range(C):
            part[c, :] = 0.0
            kind = kinds[c]
            if not free and kind != 0:
                done = False
                continue
            kh, ks, kp = _factors(kk, h, depth[c])
            s0, n = starts[c], starts[c + 1] - starts[c]
            if not (share[c] and done):  # channels of one stream share the phase
                for i in range(n):
                    j = s0 + i
                    ph = -w * T[j]
                    WE[i] = w
                    if track:
                        ph += kk * (X[j] * cb + Y[j] * sb)
                        WE[i] -= kk * (VX[j] * cb + VY[j] * sb)
                    CO[i], SI[i] = np.cos(ph), np.sin(ph)
            done = True
            for i in range(n):
                co, si, we = CO[i], SI[i], WE[i]
                if kind == 0:
                    gain = kp if not free else kp - ks
                    A[i], B[i] = gain * co, -gain * si
                elif kind == 3:
                    A[i], B[i] = -ks * we * si, -ks * we * co
                else:
                    gg = kh * we * (cb if kind == 1 else sb)
                    A[i], B[i] = gg * co, -gg * si
            if hp:
                _highpass_inplace(A, n, nhp[c], cs, tmp)
                _highpass_inplace(B, n, nhp[c], cs, tmp)
            a00 = a01 = a11 = ay = by = 0.0
            for i in range(n):
                yv = D[s0 + i]
                a00 += A[i] * A[i]
                a01 += A[i] * B[i]
                a11 += B[i] * B[i]
                ay += A[i] * yv
                by += B[i] * yv
            part[c, 0], part[c, 1], part[c, 2], part[c, 3], part[c, 4] = a00, a01, a11, ay, by
            wc = weights[c]
            M00 += wc * a00
            M01 += wc * a01
            M11 += wc * a11
            r0 += wc * ay
            r1 += wc * by
        det = M00 * M11 - M01 * M01
        c0 = c1 = 0.0
        if abs(det) > 1e-300:
            c0, c1 = (M11 * r0 - M01 * r1) / det, (M00 * r1 - M01 * r0) / det
        cc[g, 0], cc[g, 1] = c0, c1
        total = 0.0
        for c in range(C):
            p = part[c]
            r = tss[c] - 2 * (c0 * p[3] + c1 * p[4]) + c0 * c0 * p[0] + 2 * c0 * c1 * p[1]
            r += c1 * c1 * p[2]
            r = max(r, 1e-12 * tss[c] + 1e-300)
            rss[g, c] = r
            total += weights[c] * r
        chi2[g] = total
    return chi2, cc, rss


def _used(win: _Window, model: str) -> list[int]:
    return [i for i, c in enumerate(win.chans) if model == "free" or c.kind == "p"]


def _evaluate(win: _Window, model: str, omega, beta, weights, hp: bool = False, gain=1.0):
    """For G candidates: chi2 = sum_c w_c RSS_c (G,), c (G, 2), RSS (G, C); channels the model
    does not predict keep RSS = TSS. ``gain`` scales the direction vector (a fitted
    cos(beta - course) beyond +-1 on a straight track, see :func:`_fit_model`)."""
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    beta = np.broadcast_to(np.asarray(beta, dtype=float), omega.shape)
    gain = np.broadcast_to(np.asarray(gain, dtype=float), omega.shape)
    ex, ey = gain * np.cos(beta), gain * np.sin(beta)
    chi2, c, rss = _fit_kernel(omega, ex, ey, win.g, float(win.h), model == "free", hp,
                               *win.packed, weights, win.tss, win.has_track)  # fmt: skip
    return np.where(np.isfinite(chi2), chi2, np.inf), c, rss


def _ridge(win: _Window, omega_e: float, beta, gain=1.0) -> np.ndarray:
    """Intrinsic omega on the ridge omega - k V_mean . e_beta = omega_e, for each beta."""
    u = gain * (win.v_mean[0] * np.cos(beta) + win.v_mean[1] * np.sin(beta))
    return intrinsic_from_encounter(np.full(np.shape(beta), omega_e), u, win.h, win.g)


def _puv_axis(win: _Window, omega_e: float) -> list[float]:
    """Both propagation directions along the principal axis of the horizontal velocity's
    complex amplitude at omega_e (alpha = 1/2 atan2(2 S_xy, S_xx - S_yy), S the 2x2 spectral
    matrix): the PUV method's direction, 180 deg ambiguous."""
    z = {}
    for c in win.chans:
        if c.kind in ("vx", "vy"):
            z[c.kind] = (c.y * np.exp(1j * omega_e * c.t)).sum()
    if len(z) < 2:
        return [0.0, np.pi]
    sxx, syy = abs(z["vx"]) ** 2, abs(z["vy"]) ** 2
    sxy = (z["vx"] * np.conj(z["vy"])).real
    alpha = 0.5 * math.atan2(2 * sxy, sxx - syy)
    return [alpha, alpha + np.pi]


_COS_GRID = np.linspace(-1.2, 1.2, 9)


def _search_mode(win: _Window, model: str, beta_fixed) -> str:
    """ "fixed" (a given direction), "none" (no track), "cos" (rigid on a straight track: the
    model depends on beta only through c = cos(beta - course), searched in [-1.3, 1.3] so the
    estimate of c = -1 (head seas) or +1 is not pushed inward by noise, as it would be with
    |c| <= 1, which biased omega), or "beta"."""
    if beta_fixed is not None:
        return "fixed"
    if not win.has_track:
        return "none"
    return "cos" if model == "rigid" and win.straight else "beta"


def _dirs(win: _Window, mode: str, b, beta_fixed):
    """(beta, gain) arrays of the search coordinate b."""
    b = np.atleast_1d(np.asarray(b, dtype=float))
    if mode == "cos":
        return np.full(b.shape, win.course), np.clip(b, -1.3, 1.3)
    if mode == "fixed":
        return np.full(b.shape, beta_fixed[0]), np.full(b.shape, beta_fixed[1])
    return b, np.ones(b.shape)


def _initial(win: _Window, model: str, peaks, mode: str, beta_fixed):
    """Candidates: the three highest encounter peaks x the distinct velocities of the window
    (each peak may come from one leg of the track) x directions, on the ridge
    omega - k V . e_beta = omega_e (the zoom's first level spans half a resolution cell)."""
    coords = {"fixed": np.zeros(1), "none": np.zeros(1), "cos": _COS_GRID}.get(mode, _BETAS[::2])
    wes, us, be = [], [], []
    for i, we in enumerate(peaks[: 2 if mode in ("beta", "cos") and model == "rigid" else 3]):
        if model == "free" and mode == "beta":
            axis = np.array(_puv_axis(win, float(we)))
            coords = np.r_[axis, axis - np.pi / 6, axis + np.pi / 6] if i == 0 else axis
        beta, gain = _dirs(win, mode, coords, beta_fixed)
        for v in win.v_segments:
            us.append(gain * (v[0] * np.cos(beta) + v[1] * np.sin(beta)))
            wes.append(np.full(coords.shape, we))
            be.append(coords)
    be = np.concatenate(be)
    om = intrinsic_from_encounter(np.concatenate(wes), np.concatenate(us), win.h, win.g)
    good = np.isfinite(om) & (om > np.pi * F_LOW_HZ)
    return om[good], be[good]


@njit(cache=True)
def _zoom_kernel(w, b, dw, db, levels, two_d, mode, beta0, gain0, g0, h, free, packed, weights,
                 tss, track):  # fmt: skip
    """The zoom of :func:`_zoom` in one compiled loop (no Python per level)."""
    T, X, Y, VX, VY, D, starts, kinds, nhp, depth, share = packed
    m = 9 if two_d else 3
    om, ex, ey = np.empty(m), np.empty(m), np.empty(m)
    cbs = np.empty(m)
    for _ in range(levels):
        for i in range(m):
            iw, ib = (i // 3 - 1, i % 3 - 1) if two_d else (i - 1, 0)
            om[i] = max(w + iw * dw, 1e-3)
            cbs[i] = b + ib * db
            if mode == 1:  # c = cos(beta - course), clipped
                c = min(max(cbs[i], -1.3), 1.3)
                ex[i], ey[i] = c * np.cos(beta0), c * np.sin(beta0)
            elif mode == 2:  # fixed direction
                ex[i], ey[i] = gain0 * np.cos(beta0), gain0 * np.sin(beta0)
            else:
                ex[i], ey[i] = np.cos(cbs[i]), np.sin(cbs[i])
        chi2 = _fit_kernel(om, ex, ey, g0, h, free, False, T, X, Y, VX, VY, D, starts, kinds,
                           nhp, depth, share, weights, tss, track)[0]  # fmt: skip
        j = 0
        for i in range(m):
            if chi2[i] < chi2[j]:
                j = i
        w, b = om[j], cbs[j]
        dw, db = dw / 2, db / 2
    return w, b


def _zoom(win, model, weights, w, b, steps, levels, mode, beta_fixed):
    """Refine (omega, b) on 3 x 3 (or 3 x 1) grids around the best point, halved each level."""
    beta0, gain0 = beta_fixed if mode == "fixed" else (win.course, 1.0)
    code = {"beta": 0, "cos": 1}.get(mode, 2 if mode == "fixed" else 0)
    if mode == "none":
        beta0, gain0, code = float(b), 1.0, 2
    w, b = _zoom_kernel(float(w), float(b), float(steps[0]), float(steps[1]), int(levels),
                        mode in ("beta", "cos"), code, float(beta0), float(gain0), win.g,
                        float(win.h), model == "free", win.packed, weights, win.tss,
                        win.has_track)  # fmt: skip
    return float(w), float(b)


def _fit_model(win: _Window, model: str, peaks, beta_fixed=None):
    """Search, reweight by the residual variances, refine; returns a dict of the fit or None.
    ``beta_fixed``: None or (beta, gain)."""
    weights = np.where(win.tss > 0, win.n / np.maximum(win.tss, 1e-300), 0.0)
    used = _used(win, model)
    weights[[i for i in range(weights.size) if i not in used]] = 0.0
    mode = _search_mode(win, model, beta_fixed)
    om, be = _initial(win, model, peaks, mode, beta_fixed)
    if om.size == 0:
        return None
    beta, gain = _dirs(win, mode, be, beta_fixed)
    j = int(np.argmin(_evaluate(win, model, om, beta, weights, gain=gain)[0]))
    w, b = float(om[j]), float(be[j])
    steps = (np.pi / win.duration, 0.15 if mode == "cos" else np.deg2rad(10.0))
    for levels in (5, 0):  # weights 1 / sigma_c^2 from the residuals, then the zoom
        beta, gain = _dirs(win, mode, b, beta_fixed)
        rss = _evaluate(win, model, w, beta, weights, hp=True, gain=gain)[2][0]
        weights = np.zeros_like(weights)
        weights[used] = win.n[used] / np.maximum(rss[used], 1e-300)
        w, b = _zoom(win, model, weights, w, b, steps, levels, mode, beta_fixed)
    beta, gain = _dirs(win, mode, b, beta_fixed)
    chi2, c, rss = _evaluate(win, model, w, beta, weights, hp=True, gain=gain)
    loglik = -0.5 * float(np.sum(win.n * np.log(rss[0] / win.n)))
    cells = {"beta": _BETAS.size, "cos": _COS_GRID.size}.get(mode, 1)
    return {"omega": w, "beta": float(beta[0]), "gain": float(gain[0]), "mode": mode,
            "c": c[0], "rss": rss[0], "model": model, "weights": weights, "loglik": loglik,
            "cells": cells}  # fmt: skip


def _slice(data: _Data, t0: float, t1: float, omega_e: float | None) -> _Window | None:
    """The channels inside [t0, t1], times from t0, track from its value at t0, data high-passed
    over one encounter period (``omega_e``; 1 s when unknown)."""
    chans, n_hp, tss, n = [], [], [], []
    period = 2 * np.pi / omega_e if omega_e else 1.0
    vs = []
    for c in data.channels:
        i0, i1 = np.searchsorted(c.t, t0, "left"), np.searchsorted(c.t, t1, "right")
        if i1 - i0 < 8:
            continue
        nh = max(int(round(period * c.rate)), 1)
        y = c.y[i0:i1]
        prev = chans[-1] if chans else None
        same = prev is not None and prev.name == c.name and prev.t.size == i1 - i0
        t_rel = prev.t if same else c.t[i0:i1] - t0
        sub = _Channel(c.name, c.kind, t_rel, _highpass(y - y.mean(), nh), c.depth, c.rate)
        if c.x is not None:
            sub.x, sub.yy = c.x[i0:i1] - c.x[i0], c.yy[i0:i1] - c.yy[i0]
            sub.vx, sub.vy = c.vx[i0:i1], c.vy[i0:i1]
            vs.append([sub.vx.mean(), sub.vy.mean()])
        chans.append(sub)
        n_hp.append(nh)
        tss.append(float(sub.y @ sub.y))
        n.append(float(sub.y.size))
    if not chans:
        return None
    has_track = any(c.x is not None for c in chans)
    v_mean = np.mean(vs, axis=0) if vs else np.zeros(2)
    segments = [v_mean]
    track = next((c for c in chans if c.x is not None), None)
    if track is not None:
        for i in np.linspace(0, track.t.size - 1, 5).astype(int):
            v = np.array([track.vx[i], track.vy[i]])
            if all(np.hypot(*(v - s)) > 0.05 for s in segments):
                segments.append(v)
    course = float(np.arctan2(v_mean[1], v_mean[0])) if np.hypot(*v_mean) > 1e-3 else 0.0
    straight = True
    if track is not None:
        perp = -track.x * np.sin(course) + track.yy * np.cos(course)
        straight = bool(np.ptp(perp) < 0.1)
    win = _Window(chans, n_hp, np.array(tss), np.array(n), t1 - t0, has_track, v_mean,
                  segments, course, straight, data.h, data.g)  # fmt: skip
    win.pack()
    return win


def _direction_profile(win: _Window, fit: dict, weights) -> tuple[np.ndarray, np.ndarray]:
    """chi2 profile over the direction grid: each beta at its best omega, found by a 1-D zoom
    (all directions in one batch per level) from the ridge of the fitted encounter frequency."""
    w, b = fit["omega"], fit["beta"]
    k = float(wavenumber(w, win.h, win.g))
    we = w - k * (win.v_mean @ [np.cos(b), np.sin(b)])
    step = 0.5 * 2 * np.pi / win.duration
    w0 = _ridge(win, we, _BETAS)
    w0 = np.where(np.isfinite(w0), w0, np.nan)
    ok = np.isfinite(w0)
    best = np.full(_BETAS.size, np.inf)
    offs = np.array([-1.0, 0.0, 1.0])
    for _ in range(5):
        om = (w0[ok, None] + offs[None] * step).ravel()
        chi2 = _evaluate(win, fit["model"], np.maximum(om, 1e-3), np.repeat(_BETAS[ok], 3),
                         weights)[0].reshape(-1, 3)  # fmt: skip
        j = np.argmin(chi2, axis=1)
        w0[ok] = w0[ok] + offs[j] * step
        best[ok] = chi2[np.arange(j.size), j]
        step /= 2
    return best, w0


def _direction_status(win: _Window, fit: dict, course: float) -> tuple[str, list[float]]:
    """("observed" | "mirror" | "unobservable" | "omega-only", rival betas): a beta whose
    profile chi2 is within the 99.9 % level of the best and more than 30 deg away is a rival;
    rivals only at the mirror image about the course leave omega determined ("mirror"); rivals
    whose omega is within 1 % of the fit's also leave omega determined ("omega-only")."""
    if not win.has_track:
        return "unobservable", []
    if fit["model"] == "free":
        return "observed", []  # the horizontal orbital velocity's axis and phase give it
    if _steady(win):
        return "unobservable", []
    if fit["mode"] == "cos":  # straight track: only c = cos(beta - course) is observable
        c = float(np.clip(fit["gain"], -1.0, 1.0))
        if abs(c) > 0.97:
            return "observed", []
        spread = float(np.rad2deg(np.arccos(c)))
        rivals = [(np.rad2deg(course) + sign * spread) % 360 for sign in (1, -1)]
        return "mirror", rivals
    weights = fit["weights"]
    best = float(_evaluate(win, fit["model"], fit["omega"], fit["beta"], weights)[0][0])
    prof, om = _direction_profile(win, fit, weights)
    far = np.abs(wrap_angle(_BETAS - fit["beta"])) > np.deg2rad(30)
    rival = far & (prof - best < _DIR_CHI2)
    if not rival.any():
        return "observed", []
    mirror = wrap_angle(2 * course - fit["beta"])
    near_mirror = np.abs(wrap_angle(_BETAS - mirror)) <= np.deg2rad(30)
    rivals = [float(np.rad2deg(b) % 360) for b in _BETAS[rival]]
    if not (rival & ~near_mirror).any():
        return "mirror", rivals
    if np.all(np.abs(om[rival] / fit["omega"] - 1) < 0.01):
        return "omega-only", rivals
    return "unobservable", rivals


def _models(data: _Data, platform: str, notes: list[str]) -> list[str]:
    has_p = any(c.kind == "p" for c in data.channels)
    has_v = any(c.kind != "p" for c in data.channels)
    if platform == "rigid" and not has_p:
        raise DataError("platform rigid: needs the barometer (pressure stream), the log has none")
    if platform != "auto":
        return [platform]
    if not has_v:
        notes.append("barometer only: rigid mount assumed (a free vehicle's barometer sees "
                     "only a (K_p - K_s)), no direction")  # fmt: skip
        return ["rigid"]
    return ["rigid", "free"] if has_p else ["free"]


def _circular_mean(a: np.ndarray) -> float:
    return float(np.arctan2(np.sin(a).mean(), np.cos(a).mean())) if a.size else 0.0


def _calm_level(win: _Window, searched_betas: int) -> float:
    """2 ln(M / alpha): M = frequency cells (band x duration) x direction cells."""
    nyq = 0.5 * min(c.rate for c in win.chans)
    cells = max((0.9 * nyq - F_LOW_HZ) * win.duration, 1.0) * searched_betas
    return 2.0 * math.log(cells / _ALPHA)


def _fit_window(data: _Data, t0: float, t1: float, models: list[str], beta_fixed=None):
    """(best fit dict or None, the window, notes) for [t0, t1]."""
    notes: list[str] = []
    inside = []
    for c in data.channels:
        i0, i1 = np.searchsorted(c.t, t0, "left"), np.searchsorted(c.t, t1, "right")
        if i1 - i0 >= 8:
            inside.append(_Channel(c.name, c.kind, c.t[i0:i1], c.y[i0:i1], c.depth, c.rate))
    peaks, prominence = _spectrum_peaks(inside, t0, t1) if inside else (np.array([]), 0.0)
    if peaks.size == 0:
        return None, None, ["too few samples in the window for a spectrum"]
    if len(models) > 1 and prominence < MIN_VELOCITY_PEAK:
        models = ["rigid"]
        notes.append("rigid: the DVL velocity shows no orbital peak")
    omega_hp = float(peaks[0])
    for _ in range(2):  # the high-pass follows the fitted encounter frequency
        win = _slice(data, t0, t1, omega_hp)
        if win is None:
            return None, win, ["too few samples in the window for a spectrum"]
        fits = _fit_models(win, models, peaks, beta_fixed)
        if not fits:
            return None, win, ["no encounter frequency in the searched band"]
        best = max(fits, key=lambda f: f["loglik"])
        we = abs(_encounter(win, best))
        if abs(we / omega_hp - 1) < 0.2:
            break
        omega_hp, peaks = we, np.r_[we, peaks]
    if len(fits) > 1:
        other = min(fits, key=lambda f: f["loglik"])
        notes.append(f"{best['model']} fits better than {other['model']} (log-likelihood "
                     f"{best['loglik'] - other['loglik']:+.1f})")  # fmt: skip
    best["peaks"] = peaks
    _judge(win, best, beta_fixed)
    return best, win, notes


def _encounter(win: _Window, fit: dict) -> float:
    """omega_e = omega - k gain V_mean . e_beta of a fit."""
    k = float(wavenumber(fit["omega"], win.h, win.g))
    e = fit["gain"] * np.array([np.cos(fit["beta"]), np.sin(fit["beta"])])
    return float(fit["omega"] - k * (win.v_mean @ e))


def _fit_models(win: _Window, models: list[str], peaks, beta_fixed) -> list[dict]:
    """The fits of ``models``. With both, the free model first; the rigid one is first fitted
    only at the free fit's direction, and searched in full unless the free fit is better than
    that by more than ``_CLEAR_LOGLIK`` (the same wave drives the barometer either way, so the
    rigid optimum is then near the free one's and the search would not change the choice)."""
    if models != ["rigid", "free"]:
        return [f for m in models if (f := _fit_model(win, m, peaks, beta_fixed)) is not None]
    free = _fit_model(win, "free", peaks, beta_fixed)
    rigid = None
    if free is not None:
        quick = _fit_model(win, "rigid", np.array([abs(_encounter(win, free))]), _dir(free))
        if quick is not None and free["loglik"] - quick["loglik"] > _CLEAR_LOGLIK:
            rigid = quick
    rigid = rigid or _fit_model(win, "rigid", peaks, beta_fixed)
    return [f for f in (rigid, free) if f is not None]


def _judge(win: _Window, fit: dict, beta_fixed) -> None:
    """The fit's explained fraction sum_c w_c (TSS_c - RSS_c) / sum_c w_c TSS_c and the calm
    test (module doc)."""
    used = _used(win, fit["model"])
    w = fit["weights"]
    gain = float(((win.tss - fit["rss"]) * w)[used].sum())
    fit["explained"] = gain / max(float((win.tss * w)[used].sum()), 1e-300)
    fit["calm"] = gain <= _calm_level(win, fit["cells"]) or fit["explained"] < MIN_EXPLAINED


def _window_result(data, t0, t1, fit, win, notes, sensors, beta_note=None) -> WaveWindow:
    """The WaveWindow of a fit (calm if the fit is None or calm)."""
    heading = 0.0
    if data.heading is not None:
        m = (data.heading[0] >= t0) & (data.heading[0] <= t1)
        heading = _circular_mean(data.heading[1][m])
    if fit is None or fit["calm"]:
        model = fit["model"] if fit else ("rigid" if "pressure" in sensors else "free")
        notes = [*notes, "calm: no wave stands out of the noise"]
        return WaveWindow(t0, t1, 0.0, None, None, 0.0, None, None, model, sensors,
                          float(fit["explained"]) if fit else 0.0, tuple(notes))  # fmt: skip
    a, w, b = float(np.hypot(*fit["c"])), fit["omega"], fit["beta"]
    if fit["gain"] < 0:  # a fitted cos(beta - course) < 0: the waves come from ahead
        b = b + np.pi
    we = _encounter(win, fit)
    if we <= 0:
        notes.append("encounter frequency <= 0: the vehicle outruns the waves (assumed not)")
    direction = relative = None
    if fit.get("direction_known", False) and win.has_track:
        relative = float(180.0 - (180.0 - np.rad2deg(wrap_angle(b - heading))) % 360)
        if data.frame == "world":
            direction = float(np.rad2deg(b) % 360)
    if beta_note:
        notes.append(beta_note)
    return WaveWindow(
        float(t0), float(t1), a, float(w / (2 * np.pi)), float(abs(we) / (2 * np.pi)),
        2.0 * math.sqrt(2.0) * a, direction, relative, fit["model"], sensors,
        float(fit["explained"]), tuple(notes),
    )  # fmt: skip


def _estimate_window(data: _Data, t0: float, t1: float, models: list[str]):
    """Pass 1 of one window: (WaveWindow, (beta, gain) if omega is determined else None, the
    beam-sea direction, window and fit if the window needs pass 2 else None)."""
    fit, win, notes = _fit_window(data, t0, t1, models)
    sensors = _sensors_used(data, fit)
    if fit is None or fit["calm"]:
        return _window_result(data, t0, t1, fit, win, notes, sensors), None, None, None
    course = _course(win)
    status, rivals = _direction_status(win, fit, course)
    fit["direction_known"] = status == "observed"
    if status == "observed" or not win.has_track:
        if not win.has_track and fit["model"] == "rigid":
            notes.append("no track: frequency is the encounter frequency (vehicle assumed at "
                         "rest), direction not observable")  # fmt: skip
        return (
            _window_result(data, t0, t1, fit, win, notes, sensors),
            _dir(fit),
            None,
            (win, fit),
            (win, fit),
        )
    shown = ", ".join(f"{r:.0f}" for r in rivals[:6])
    if status in ("mirror", "omega-only"):
        notes.append(f"direction not observable (also fits beta = {shown} deg)")
        # omega is determined: the fitted direction serves neighbours on the same course
        return _window_result(data, t0, t1, fit, win, notes, sensors), _dir(fit), None, (win, fit)
    fit["direction_known"] = False
    # pass 2 refits at a neighbour's direction, or for beam seas (course + 90 deg)
    result = _window_result(data, t0, t1, fit, win, notes, sensors)
    return result, None, ((course + np.pi / 2, 1.0), win, fit), (win, fit)


def _steady(win: _Window) -> bool:
    """Constant velocity over the window: the mean velocities of its thirds agree within
    0.05 m/s (means, so the DVL noise averages out). Then only omega_e is observable, and a
    fit would favour beam seas, whose phase does not feel the track's integrated noise."""
    track = next((c for c in win.chans if c.x is not None), None)
    if track is None:
        return True
    thirds = np.array_split(np.arange(track.t.size), 3)
    means = np.array([[track.vx[i].mean(), track.vy[i].mean()] for i in thirds])
    return bool(np.max(np.hypot(*(means - means.mean(axis=0)).T)) < 0.05)


def _course(win: _Window) -> float:
    return win.course


def _dir(fit: dict) -> tuple[float, float]:
    """(beta, gain) of a fit, for a neighbour's fixed direction."""
    return fit["beta"], fit["gain"]


def _sensors_used(data: _Data, fit) -> tuple[str, ...]:
    if fit is not None and fit["model"] == "rigid":
        return tuple(s for s in data.sensors if s != "imu" or data.vel is not None)
    return data.sensors


def _pool_straight(data: _Data, first: list) -> list:
    """Pass 2a: on a straight track a rigid window sees the direction only through
    c = cos(beta - course), and only while the speed changes; its c is noisy. The median c of
    the windows where it was determined, over the windows on the same course (within 10 deg),
    is the estimate for each of them (the sea's direction is assumed steady meanwhile): each
    is refitted with it. Only the nearest ``POOL_WINDOWS`` informed windows on each side count,
    so a slowly turning sea is followed. Returns ``first`` with those windows replaced."""
    out = list(first)
    fits = [(i, f[3][1]) for i, f in enumerate(first) if f[3] is not None]
    informed = [(i, fit) for i, fit in fits if fit["mode"] == "cos" and first[i][1] is not None]
    keys = [i for i, _ in informed]
    for i, fit in fits:
        if fit["mode"] != "cos" or fit["model"] != "rigid":
            continue
        win = first[i][3][0]
        near = informed[max(bisect.bisect_left(keys, i) - POOL_WINDOWS, 0) :][: 2 * POOL_WINDOWS]
        same = [f for _, f in near if abs(wrap_angle(f["beta"] - fit["beta"])) < 0.17]
        if not same or (len(same) == 1 and same[0] is fit):
            continue
        c = float(np.median([f["gain"] for f in same]))
        refit = _fit_model(win, "rigid", fit["peaks"], beta_fixed=(fit["beta"], c))
        if refit is None:
            continue
        _judge(win, refit, True)
        refit["direction_known"] = abs(c) > 0.97
        w = first[i][0]
        notes = [n for n in w.notes if not n.startswith("direction not observable")]
        note = (f"straight track: cos(beta - course) = {c:+.2f}, the median over {len(same)} "
                "windows where the speed changes")  # fmt: skip
        if abs(c) <= 0.97:
            note += f" (beta = course +- {np.rad2deg(np.arccos(np.clip(c, -1, 1))):.0f} deg)"
        result = _window_result(data, w.t_start, w.t_end, refit, win, notes, w.sensors, note)
        out[i] = (result, first[i][1], None, first[i][3])
    return out


def _consensus_free(data: _Data, first: list) -> list:
    """Pass 2b: a free window whose direction is more than 45 deg from the circular median of
    its neighbours' (``POOL_WINDOWS`` each side) is refitted at that median; the refit is kept
    when its log-likelihood is within ``_CONSENSUS_LOGLIK`` of the window's own (a likelihood
    ratio test at about 99.99 % for 2 parameters): where the horizontal orbital velocity is
    near the DVL's noise (a deep vehicle, following seas), the ridge omega - k V . e_beta =
    omega_e lets a wrong direction and frequency fit nearly as well, and the sea's direction
    is steadier than that."""
    out = list(first)
    free = [(i, f[3][1]) for i, f in enumerate(first) if f[3] is not None
            and f[3][1]["model"] == "free" and f[1] is not None]  # fmt: skip
    for n, (i, fit) in enumerate(free):
        others = [f["beta"] for j, f in free[max(n - POOL_WINDOWS, 0) : n + POOL_WINDOWS + 1]
                  if j != i]  # fmt: skip
        if len(others) < 2:
            continue
        centre = _circular_median(np.array(others))
        if abs(wrap_angle(fit["beta"] - centre)) <= np.pi / 4:
            continue
        win = first[i][3][0]
        refit = _fit_model(win, "free", fit["peaks"], beta_fixed=(centre, 1.0))
        if refit is None or refit["loglik"] < fit["loglik"] - _CONSENSUS_LOGLIK:
            continue
        _judge(win, refit, True)
        refit["direction_known"] = True
        w = first[i][0]
        note = (f"direction {np.rad2deg(fit['beta']) % 360:.0f} deg replaced by the neighbours' "
                f"{np.rad2deg(centre) % 360:.0f} deg (log-likelihood "
                f"{refit['loglik'] - fit['loglik']:+.1f})")  # fmt: skip
        result = _window_result(data, w.t_start, w.t_end, refit, win, list(w.notes), w.sensors,
                                note)  # fmt: skip
        out[i] = (result, _dir(refit), None, (win, refit))
    return out


def _circular_median(a: np.ndarray) -> float:
    """The element of ``a`` minimizing the sum of angular distances to the others."""
    d = np.abs(wrap_angle(a[:, None] - a[None, :])).sum(axis=1)
    return float(a[int(np.argmin(d))])


def _borrow(data, windows, betas, needs) -> list[WaveWindow]:
    """Pass 2: a window whose direction is not observable (``needs``: its beam-sea direction,
    window and fit) is refitted at the nearest observed window's direction, else for beam
    seas."""
    have = [i for i, b in enumerate(betas) if b is not None]
    known = [w.relative_direction_deg is not None for w in windows]
    out = list(windows)
    for i, beam in enumerate(needs):
        if beam is None:
            continue
        w = windows[i]
        if have:
            j = min(have, key=lambda j: abs(j - i))
            beta, known_j = betas[j], known[j]
            note = (f"direction not observable in this window: taken from the window "
                    f"{windows[j].t_start:.1f}-{windows[j].t_end:.1f} s")  # fmt: skip
        elif np.hypot(*beam[1].v_mean) < 0.05:
            beta, known_j = beam[0], False
            note = "vehicle at rest: the encounter frequency is the wave frequency; no direction"
        else:
            beta, known_j = beam[0], False
            note = ("direction not observable (steady course and speed): frequency from the "
                    "encounter frequency for beam seas")  # fmt: skip
        win, first = beam[1], beam[2]
        fit = _fit_model(win, first["model"], first["peaks"], beta_fixed=beta)
        if fit is None:
            continue
        _judge(win, fit, beta)
        notes = [n for n in w.notes if not n.startswith("direction not observable")]
        fit["direction_known"] = known_j
        out[i] = _window_result(data, w.t_start, w.t_end, fit, win, notes, w.sensors, note)
    return out


def _window_edges(t0: float, t1: float, length: float, step: float) -> list[tuple[float, float]]:
    span = t1 - t0
    if span < 1.5 * length:
        return [(t0, t1)]
    n = int(math.ceil((span - length) / step)) + 1
    starts = np.linspace(t0, t1 - length, n)
    return [(float(s), float(s + length)) for s in starts]


def estimate_sea_state(
    log: Log,
    *,
    platform: str = "auto",
    window_periods: float = 20.0,
    step_fraction: float = 0.5,
    water_depth_m: float | None = None,
    water_density_kg_m3: float | None = None,
    t_start: float | None = None,
    t_end: float | None = None,
) -> SeaStateEstimate:
    """Estimate the wave condition (a, f, beta) per window from the robot's own sensors (see the
    module docstring for the model). ``platform``: "rigid" (held firm: barometer reads
    a K_p), "free" (rides the orbit: DVL sees it), or "auto" (the likelier, per window)."""
    _check_options(platform, window_periods, step_fraction, water_depth_m, water_density_kg_m3,
                   t_start, t_end)  # fmt: skip
    if not isinstance(log, Log):
        raise ConfigError(f"estimate_sea_state: expected a Log, got {type(log).__name__}")
    rho = water_density_kg_m3 or log.metadata.get("water_density_kg_m3") or FRESH_WATER_DENSITY
    if not _finite(rho):
        rho = FRESH_WATER_DENSITY
    data = _prepare(_crop(log, t_start, t_end), float(rho), water_depth_m)
    t0 = min(float(c.t[0]) for c in data.channels)
    t1 = max(float(c.t[-1]) for c in data.channels)
    peaks, _ = _spectrum_peaks(data.channels, t0, t1, 1)
    notes = list(dict.fromkeys(data.notes))
    period = 2 * np.pi / float(peaks[0]) if peaks.size else 1.0
    if t1 - t0 < 3 * period:
        raise DataError(
            f"sea-state estimate: the log spans {t1 - t0:.1f} s, less than 3 wave periods "
            f"({3 * period:.1f} s)"
        )
    _attach_track(data, period)
    models = _models(data, platform, notes)
    notes.append(f"window length from the whole log's encounter period {period:.2f} s")
    length = float(window_periods) * period
    edges = _window_edges(t0, t1, length, float(step_fraction) * length)
    first = _pool_straight(data, [_estimate_window(data, a, b, models) for a, b in edges])
    first = _consensus_free(data, first)
    windows = _borrow(data, [f[0] for f in first], [f[1] for f in first], [f[2] for f in first])
    step = edges[1][0] - edges[0][0] if len(edges) > 1 else t1 - t0
    return SeaStateEstimate(windows, edges[0][1] - edges[0][0], step, notes)


__all__ = ["PLATFORMS", "SeaStateEstimate", "WaveWindow", "estimate_sea_state"]
