"""Wave characterization (the paper's Table I, section IV-B): wave probe + sensor logs -> noise.

For each run:

- Wave frequency f_p: the peak of the wave-probe periodogram (Hann window, zero-padded 8x,
  parabolic interpolation of the log-peak), the paper's "wave frequency".
- Wave amplitude a: from the spectrum, a = sqrt(2 m_0) with m_0 the elevation variance (for a
  linear wave eta = a cos(theta), var(eta) = a^2 / 2); also by zero crossings, a = mean crest-to-
  trough height / 2 over the zero-up-crossing waves, which is robust to a slow drift.
- Calm water: a probe whose amplitude is below :data:`CALM_AMPLITUDE_M`, or whose spectral peak
  does not stand above the noise (peak below :data:`PEAK_TO_NOISE_MIN` times the median of the
  periodogram), shows no wave; the run is calm and has no wave frequency (the peak of a flat
  noise spectrum is a random bin, e.g. 13 Hz).
- DVL standard deviation per axis (DVL frame) during the wave segment:
  * with ground truth, about the TRUE motion (ground truth expressed in the DVL frame)
    restricted to the constant-speed phase (smoothed |acceleration| below a threshold and speed
    above half the run's maximum), so neither the motion, the acceleration phases nor a
    speed-proportional scale error inflate it;
  * without ground truth, about the DVL itself: the constant-speed segments are found from the
    DVL (running median of the speed within 5 % of the cruise speed, the median speed of the
    moving samples), and inside them each sample is compared with the centred running mean of n
    samples over W = max(4 wave periods, 4 s). For white noise of variance s^2 the residual
    x_i - mean_n has variance s^2 (1 - 1/n), so s^2 is estimated by mean(r^2) / (1 - 1/n). Real
    motion at the wave frequency (e.g. a mount swaying in the waves) cannot be told from noise
    without ground truth and counts as noise.
- The barometer's wave-induced depth noise (not in the paper): std of depth(p) - true depth;
  without ground truth, depth(p) about its centred running mean over W = max(10 wave periods,
  10 s) with the same (1 - 1/n) correction. A linear wave adds rho g a K_p(d) cos(theta) to the
  pressure, K_p(d) = cosh(k(h - d)) / cosh(k h), so the expected value is
  sqrt((a K_p)^2 / 2 + (s_p / (rho g))^2) for a sensor noise s_p.

``wave_noise`` subtracts a calm run's sensor noise in quadrature when one is given, so the profile
holds the EXTRA noise gamma the filter adds; otherwise it holds the total (and says so).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import periodogram

from ..errors import DataError
from ..log import FRESH_WATER_DENSITY, Log, WaveProbe
from .noise import NoiseProfile, wave_name
from .noise_physics import sensor_site

CALM_AMPLITUDE_M = 0.01  # a probe showing less than this is calm water
PEAK_TO_NOISE_MIN = 100.0  # a wave's spectral peak over the median periodogram level
STEADY_SPEED_TOLERANCE = 0.05  # constant-speed segment: within 5 % of the cruise speed


@dataclass(frozen=True)
class WaveEstimate:
    """Wave amplitude (spectral and zero-crossing) and peak frequency; ``calm`` when the probe
    shows no wave, in which case ``frequency_hz`` is None."""

    amplitude_m: float
    amplitude_zero_crossing_m: float
    frequency_hz: float | None
    calm: bool = False
    peak_to_noise: float = float("inf")


@dataclass(frozen=True)
class RunCharacterization:
    """One run: its waves and the measured noise of each acoustic measurement."""

    source: str
    wave: WaveEstimate | None
    dvl_std_m_s: tuple[float, float, float]
    dvl_samples: int
    depth_std_m: float | None
    reference: str
    notes: list[str] = field(default_factory=list)
    # the onboard estimate (undertow.seastate) over the whole run: amplitude_m,
    # frequency_hz, windows, platform; the probe's condition when there is one is the reference
    onboard: dict | None = None

    @property
    def calm(self) -> bool:
        """No wave probe, or a probe that shows no wave."""
        return self.wave is None or self.wave.calm

    def to_dict(self) -> dict:
        return asdict(self)


def estimate_waves(probe: WaveProbe) -> WaveEstimate:
    """Amplitude and peak frequency of the wave-probe elevation (see module docstring)."""
    ok = np.isfinite(probe.elevation)
    if ok.sum() < 16:
        raise DataError("wave_probe: fewer than 16 finite samples, cannot estimate waves")
    eta = probe.elevation[ok] - np.mean(probe.elevation[ok])
    fs = probe.rate_hz
    f, S = periodogram(eta, fs=fs, window="hann", nfft=8 * eta.size, detrend="linear")
    k = int(np.argmax(S[1:])) + 1
    if 1 <= k < S.size - 1 and S[k - 1] > 0 and S[k + 1] > 0:
        a, b, c = np.log(S[k - 1]), np.log(S[k]), np.log(S[k + 1])
        shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    else:
        shift = 0.0
    f_peak = float(f[k] + shift * (f[1] - f[0]))
    amplitude = float(np.sqrt(2.0 * np.var(eta)))
    floor = float(np.median(S[1:]))
    ratio = float(S[k] / floor) if floor > 0 else float("inf")
    calm = amplitude < CALM_AMPLITUDE_M or ratio < PEAK_TO_NOISE_MIN
    return WaveEstimate(
        amplitude, _zero_crossing_amplitude(eta), None if calm else f_peak, calm, ratio
    )


def _zero_crossing_amplitude(eta: np.ndarray) -> float:
    """Mean of (crest - trough) / 2 over waves delimited by zero up-crossings."""
    up = np.flatnonzero((eta[:-1] < 0) & (eta[1:] >= 0))
    if up.size < 2:
        return float("nan")
    heights = [eta[i:j].max() - eta[i:j].min() for i, j in zip(up[:-1], up[1:], strict=True)]
    return float(np.mean(heights) / 2.0)


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    n = max(int(n) | 1, 1)
    pad = n // 2
    padded = np.pad(x, ((pad, pad), (0, 0)), mode="edge")
    kernel = np.ones(n) / n
    return np.stack([np.convolve(padded[:, i], kernel, "valid") for i in range(x.shape[1])], 1)


def _odd_samples(seconds: float, rate_hz: float, minimum: int = 5) -> int:
    """An odd number of samples >= ``minimum`` spanning about ``seconds``."""
    n = int(round(seconds * rate_hz)) if np.isfinite(rate_hz) else minimum
    return max(n, minimum) | 1


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _residual_variance(x: np.ndarray, segments: list[tuple[int, int]], n: int):
    """White-noise variance of ``x`` (N, k) about its centred running mean of ``n`` (odd)
    samples, inside each segment (windows entirely inside it): mean(r^2) / (1 - 1/n), and the
    number of residuals used."""
    h = n // 2
    sums, count = np.zeros(x.shape[1]), 0
    for i0, i1 in segments:
        if i1 - i0 < n:
            continue
        c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x[i0:i1]]), axis=0)
        mean = (c[n:] - c[:-n]) / n  # window [j, j + n) centred on j + h
        r = x[i0 + h : i1 - h] - mean
        sums += np.sum(r * r, axis=0)
        count += r.shape[0]
    if count == 0:
        return np.full(x.shape[1], np.nan), 0
    return sums / count / (1.0 - 1.0 / n), count


def _steady_segments(speed: np.ndarray, n: int) -> list[tuple[int, int]]:
    """Constant-speed segments found from the measured speed itself: the running median (n
    samples) within :data:`STEADY_SPEED_TOLERANCE` of the cruise speed (median over the samples
    moving faster than half the maximum), or the whole log when the robot never moves."""
    smooth = median_filter(speed, size=n, mode="nearest")
    moving = smooth > max(0.05, 0.5 * float(smooth.max()))
    if moving.sum() < n:
        return [(0, speed.size)]
    cruise = float(np.median(smooth[moving]))
    steady = np.abs(smooth - cruise) < STEADY_SPEED_TOLERANCE * cruise
    return _runs(steady)


def characterize_run(
    log: Log, max_accel_m_s2: float = 0.02, water_density: float = FRESH_WATER_DENSITY
):
    """Characterize one run (needs dvl; wave_probe, ground_truth, pressure used when present)."""
    log.require("dvl", stage="characterize")
    notes: list[str] = []
    wave = estimate_waves(log.wave_probe) if log.wave_probe is not None else None
    onboard = onboard_waves(log, notes)
    if wave is None and onboard is not None:
        wave = WaveEstimate(
            onboard["amplitude_m"], float("nan"), onboard["frequency_hz"],
            calm=onboard["frequency_hz"] is None,
        )  # fmt: skip
        notes.append(
            "no wave_probe stream: wave condition estimated from the onboard sensors "
            f"({', '.join(onboard['sensors'])}; {onboard['windows']} window(s))"
        )
    elif wave is None:
        notes.append("no wave_probe stream: wave amplitude and frequency unknown (taken as calm)")
    elif wave.calm:
        notes.append(
            f"wave probe shows no wave (amplitude {wave.amplitude_m:.4f} m, spectral peak "
            f"{wave.peak_to_noise:.0f}x the noise level): calm run"
        )
    period = 1.0 / wave.frequency_hz if wave is not None and not wave.calm else None
    if log.ground_truth is not None:
        std, count, reference = _dvl_about_truth(log, period, max_accel_m_s2)
        depth_std = _depth_about_truth(log, water_density)
    else:
        std, count, reference = _dvl_about_itself(log, period)
        depth_std = _depth_about_itself(log, period, water_density)
        notes.append(f"no ground_truth stream: DVL noise measured about {reference}")
    if count < 10:
        raise DataError(_too_few_samples(log, count, max_accel_m_s2))
    return RunCharacterization(
        onboard=onboard,
        source=log.source,
        wave=wave,
        dvl_std_m_s=tuple(float(s) for s in std),
        dvl_samples=int(count),
        depth_std_m=depth_std,
        reference=reference,
        notes=notes,
    )


def onboard_waves(log: Log, notes: list[str]) -> dict | None:
    """The onboard sea-state estimate (:func:`undertow.seastate.estimate_sea_state`)
    over the whole run, summarized: the median over windows of amplitude and frequency (calm:
    frequency None) and the streams used. None, with a note, when it cannot be made."""
    from ..errors import UndertowError
    from ..seastate import estimate_sea_state

    try:
        est = estimate_sea_state(log)
    except UndertowError as exc:
        notes.append(f"onboard wave estimate not available: {exc}")
        return None
    if not est.windows:
        notes.append("onboard wave estimate not available: no window")
        return None
    a = float(np.median([w.amplitude_m for w in est.windows]))
    f = [w.frequency_hz for w in est.windows if w.frequency_hz is not None]
    sensors = sorted({s for w in est.windows for s in w.sensors})
    return {
        "amplitude_m": a,
        "frequency_hz": float(np.median(f)) if f and a > 0 else None,
        "windows": len(est.windows),
        "platform": est.windows[0].platform,
        "sensors": sensors,
    }


def _too_few_samples(log: Log, count: int, max_accel_m_s2: float) -> str:
    """Why fewer than 10 DVL samples could be used: too few valid ones, or (the usual case) no
    constant-speed segment, where the noise is measured."""
    name = log.source or "log"
    valid = int(_dvl_ok(log).sum())
    if valid < 10:
        return f"{name}: fewer than 10 valid DVL samples ({valid}) to characterize"
    if log.ground_truth is not None:
        rule = (
            f"from the ground truth: smoothed |acceleration| below {max_accel_m_s2:g} m/s^2 "
            "at over half the top speed"
        )
    else:
        rule = (
            f"from the DVL: speed within {STEADY_SPEED_TOLERANCE:.0%} of the cruise speed for "
            "at least one averaging window (4 wave periods, >= 4 s)"
        )
    return (
        f"{name}: no constant-speed segment ({rule}) among its {valid} valid DVL samples "
        f"({count} usable): the noise is measured at constant speed, so characterize needs "
        "runs at a steady speed (e.g. a straight carriage run), not turns or manoeuvres"
    )


def _dvl_ok(log: Log) -> np.ndarray:
    return log.dvl.valid & np.all(np.isfinite(log.dvl.velocity), axis=1)


def _dvl_about_truth(log: Log, period: float | None, max_accel_m_s2: float):
    """DVL - ground truth in the DVL frame during the constant-speed phase."""
    dvl, gt = log.dvl, log.ground_truth
    keep = _dvl_ok(log) & (dvl.t >= gt.t[0]) & (dvl.t <= gt.t[-1])
    v_world = gt.differentiated_velocity()
    accel = np.gradient(v_world, gt.t, axis=0)
    # smoothed over two wave periods, so the wave-frequency sway of a mount is not "acceleration"
    window_s = max(0.5, 2.0 * period) if period else 0.5
    steady_full = np.linalg.norm(_moving_average(accel, window_s * gt.rate_hz), axis=1)
    steady = np.interp(dvl.t, gt.t, steady_full) < max_accel_m_s2
    # moving at cruise speed: a sound-speed scale error makes the offset speed-dependent,
    # so mixing rest and cruise would inflate the std
    speed = np.linalg.norm(v_world, axis=1)
    cruising = np.interp(dvl.t, gt.t, speed) > max(0.05, 0.5 * float(speed.max()))
    keep &= steady & cruising
    v_body = gt.body_velocity(dvl.t[keep], v_world)
    residual = dvl.velocity[keep] - v_body @ log.mounting.dvl.rotation_matrix()
    if residual.shape[0] < 2:
        return np.full(3, np.nan), residual.shape[0], "ground truth, constant-speed phase"
    return np.std(residual, axis=0, ddof=1), residual.shape[0], "ground truth, constant-speed phase"


def _dvl_about_itself(log: Log, period: float | None):
    """DVL about its own running mean inside the constant-speed segments (module docstring)."""
    dvl = log.dvl
    ok = _dvl_ok(log)
    v = dvl.velocity[ok]
    rate = dvl.select(ok).rate_hz if ok.sum() > 1 else float("nan")
    window_s = max(4.0 * period, 4.0) if period else 4.0
    n = _odd_samples(window_s, rate)
    if v.shape[0] < n:
        return np.full(3, np.nan), 0, "its running mean"
    t = dvl.t[ok]
    gaps = np.flatnonzero(np.diff(t) > 1.5 / rate) + 1  # dropped reports split a segment
    segments = [
        (int(a), int(b))
        for i0, i1 in _steady_segments(np.linalg.norm(v, axis=1), n)
        for a, b in zip(
            [i0, *gaps[(gaps > i0) & (gaps < i1)]],
            [*gaps[(gaps > i0) & (gaps < i1)], i1],
            strict=True,
        )
    ]
    variance, count = _residual_variance(v, segments, n)
    reference = (
        f"its running mean over {n} samples ({window_s:.1f} s) in the constant-speed "
        "segments found from the DVL (no ground truth)"
    )
    return np.sqrt(variance), count, reference


def _depth_about_truth(log: Log, water_density: float) -> float | None:
    p, gt = log.pressure, log.ground_truth
    if p is None:
        return None
    inside = (p.t >= gt.t[0]) & (p.t <= gt.t[-1]) & np.isfinite(p.pressure)
    if inside.sum() < 2:
        return None
    true_depth = np.interp(p.t[inside], gt.t, gt.position[:, 2])
    return float(np.std(p.depth(water_density)[inside] - true_depth, ddof=1))


def _depth_about_itself(log: Log, period: float | None, water_density: float) -> float | None:
    p = log.pressure
    if p is None:
        return None
    ok = np.isfinite(p.pressure)
    if ok.sum() < 2:
        return None
    depth = p.depth(water_density)[ok][:, None]
    window_s = max(10.0 * period, 10.0) if period else 10.0
    n = _odd_samples(window_s, p.select(ok).rate_hz)
    variance, count = _residual_variance(depth, _runs(np.ones(depth.shape[0], bool)), n)
    return float(np.sqrt(variance[0])) if count >= 10 else None


def wave_noise(run: RunCharacterization, calm: RunCharacterization | None) -> tuple[float, ...]:
    """Extra DVL noise gamma per axis: sqrt(max(sigma_wave^2 - sigma_calm^2, 0)) (or the total)."""
    if calm is None:
        return run.dvl_std_m_s
    return tuple(
        float(np.sqrt(max(w**2 - c**2, 0.0)))
        for w, c in zip(run.dvl_std_m_s, calm.dvl_std_m_s, strict=True)
    )


@dataclass(frozen=True)
class Characterization:
    """All runs, the calm reference among them (if any) and the resulting noise profile."""

    runs: list[RunCharacterization]
    calm: RunCharacterization | None
    profile: NoiseProfile

    def table(self) -> list[dict]:
        """Rows of the paper's Table I: amplitude, frequency, DVL std (total and extra), depth."""
        rows = []
        for run in self.runs:
            extra = wave_noise(run, self.calm) if run is not self.calm else (0.0, 0.0, 0.0)
            rows.append(
                {
                    "source": run.source,
                    "calm": run.calm,
                    "amplitude_m": run.wave.amplitude_m if run.wave else None,
                    "amplitude_zero_crossing_m": (
                        run.wave.amplitude_zero_crossing_m if run.wave else None
                    ),
                    "frequency_hz": run.wave.frequency_hz if run.wave else None,
                    "onboard_amplitude_m": run.onboard["amplitude_m"] if run.onboard else None,
                    "onboard_frequency_hz": (run.onboard["frequency_hz"] if run.onboard else None),
                    "dvl_std_m_s": list(run.dvl_std_m_s),
                    "dvl_extra_std_m_s": list(extra),
                    "depth_std_m": run.depth_std_m,
                    "samples": run.dvl_samples,
                    "reference": run.reference,
                    "notes": list(run.notes),
                }
            )
        return rows


def characterize(logs: list[Log], name: str = "characterized") -> Characterization:
    """Characterize every run; the calmest calm run (no wave probe, or a probe showing no wave)
    is the reference whose noise is subtracted in quadrature; the rest become profile conditions
    at their MEASURED amplitude and frequency."""
    if not logs:
        raise DataError("characterize: no logs given")
    runs = [characterize_run(log) for log in logs]

    def amplitude(run):
        return run.wave.amplitude_m if run.wave else 0.0

    calm_runs = [r for r in runs if r.calm]
    calm = min(calm_runs, key=amplitude) if calm_runs else None
    conditions = [{"name": "calm", "amplitude_m": 0.0, "frequency_hz": None, "dvl_std": [0.0] * 3}]
    for run in runs:
        if run.calm:
            continue
        conditions.append(
            {
                "name": wave_name(run.wave.amplitude_m, run.wave.frequency_hz),
                "amplitude_m": run.wave.amplitude_m,
                "frequency_hz": run.wave.frequency_hz,
                "dvl_std": list(wave_noise(run, calm)),
            }
        )
    if calm is None:
        warnings.warn(
            "no calm run among the logs: the profile holds total, not extra, noise", stacklevel=2
        )
    how = "extra noise over the calm run" if calm else "total noise (no calm run given)"
    source = f"undertow characterize: {how}; runs: " + ", ".join(r.source for r in runs)
    site = characterized_site([log for log, run in zip(logs, runs, strict=True) if not run.calm])
    profile = NoiseProfile.from_dict(
        {"name": name, "source": source, **site, "conditions": conditions}
    )
    return Characterization(runs, calm, profile)


def characterized_site(wave_logs: list[Log]) -> dict:
    """The DVL and water depth the wave runs were characterized at (the profile's
    ``sensor_depth_m``, ``water_depth_m``, used to extrapolate outside its conditions): the
    median over the runs of each run's :func:`~undertow.estimation.noise_physics.sensor_site`;
    {} when a run has no depth source (the profile then assumes the paper's), no water depth
    when one is unknown."""
    sites = [sensor_site(log) for log in wave_logs]
    if not sites or any(s is None for s in sites):
        return {}
    out = {"sensor_depth_m": float(np.median([s.sensor_depth_m for s in sites]))}
    h = [s.water_depth_m for s in sites]
    if all(np.isfinite(h)) and float(np.median(h)) >= out["sensor_depth_m"]:
        out["water_depth_m"] = float(np.median(h))
    return out
