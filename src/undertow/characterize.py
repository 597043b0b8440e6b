"""Wave characterization (the paper's Table I, section IV-B): wave probe + sensor logs -> noise.

For each run:

- Wave frequency f_p: the peak of the wave-probe periodogram (Hann window, zero-padded 8x,
  parabolic interpolation of the log-peak), the paper's "wave frequency".
- Wave amplitude a: from the spectrum, a = sqrt(2 m_0) with m_0 the elevation variance (for a
  linear wave eta = a cos(theta), var(eta) = a^2 / 2); also by zero crossings, a = mean crest-to-
  trough height / 2 over the zero-up-crossing waves, which is robust to a slow drift.
- DVL standard deviation per axis (DVL frame) during the wave segment, taken about the TRUE motion
  (ground truth expressed in the DVL frame) restricted to the constant-speed phase (|acceleration|
  below a threshold and speed above half the run's maximum), so neither the motion, the
  acceleration phases nor a speed-proportional scale error inflate it. Without ground
  truth the reference is a centred moving average over two wave periods.
- The barometer's wave-induced depth noise (not in the paper): std of depth(p) - true depth.

``wave_noise`` subtracts a calm run's sensor noise in quadrature when one is given, so the profile
holds the EXTRA noise gamma the filter adds; otherwise it holds the total (and says so).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.signal import periodogram

from .errors import DataError
from .estimation.noise import NoiseProfile, wave_name
from .evaluation.trajectory import ground_truth_velocity, interpolate_ground_truth
from .log import Log, WaveProbe
from .rotations import rpy_to_matrix


@dataclass(frozen=True)
class WaveEstimate:
    amplitude_m: float
    amplitude_zero_crossing_m: float
    frequency_hz: float


@dataclass(frozen=True)
class RunCharacterization:
    """One run: its waves and the measured noise of each acoustic measurement."""

    source: str
    wave: WaveEstimate | None
    dvl_std_mps: tuple[float, float, float]
    dvl_samples: int
    depth_std_m: float | None
    reference: str
    notes: list[str] = field(default_factory=list)

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
    return WaveEstimate(amplitude, _zero_crossing_amplitude(eta), f_peak)


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


def characterize_run(log: Log, max_accel_mps2: float = 0.02, water_density: float = 997.0):
    """Characterize one run (needs dvl; wave_probe, ground_truth, pressure used when present)."""
    log.require("dvl", stage="characterize")
    notes: list[str] = []
    wave = estimate_waves(log.wave_probe) if log.wave_probe is not None else None
    if wave is None:
        notes.append("no wave_probe stream: wave amplitude and frequency unknown")
    dvl = log.dvl
    keep = dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
    gt = log.ground_truth
    depth_std = None
    if gt is not None:
        keep &= (dvl.t >= gt.t[0]) & (dvl.t <= gt.t[-1])
        v_world = ground_truth_velocity(gt)
        accel = np.gradient(v_world, gt.t, axis=0)
        steady_full = np.linalg.norm(_moving_average(accel, 0.5 * gt.rate_hz), axis=1)
        steady = np.interp(dvl.t, gt.t, steady_full) < max_accel_mps2
        # moving at cruise speed: a sound-speed scale error makes the offset speed-dependent,
        # so mixing rest and cruise would inflate the std
        speed = np.linalg.norm(v_world, axis=1)
        cruising = np.interp(dvl.t, gt.t, speed) > max(0.05, 0.5 * float(speed.max()))
        keep &= steady & cruising
        _, rpy, vel = interpolate_ground_truth(gt, dvl.t[keep], v_world)
        v_body = np.einsum("nji,nj->ni", rpy_to_matrix(rpy), vel)
        reference = v_body @ log.mounting.dvl.rotation_matrix()
        residual = dvl.velocity[keep] - reference
        ref_name = "ground truth, constant-speed phase"
        if log.pressure is not None:
            p = log.pressure
            inside = (p.t >= gt.t[0]) & (p.t <= gt.t[-1]) & np.isfinite(p.pressure)
            true_depth = np.interp(p.t[inside], gt.t, gt.position[:, 2])
            depth_std = float(np.std(p.depth(water_density)[inside] - true_depth, ddof=1))
    else:
        period = 1.0 / wave.frequency_hz if wave else 2.0
        v = dvl.velocity[keep]
        residual = v - _moving_average(v, 2 * period * dvl.rate_hz)
        ref_name = "moving average over two wave periods (no ground truth)"
        notes.append("no ground_truth stream: DVL noise measured about a moving average")
    if residual.shape[0] < 10:
        raise DataError(f"{log.source or 'log'}: fewer than 10 usable DVL samples to characterize")
    std = tuple(float(s) for s in np.std(residual, axis=0, ddof=1))
    return RunCharacterization(
        source=log.source,
        wave=wave,
        dvl_std_mps=std,
        dvl_samples=int(residual.shape[0]),
        depth_std_m=depth_std,
        reference=ref_name,
        notes=notes,
    )


def wave_noise(run: RunCharacterization, calm: RunCharacterization | None) -> tuple[float, ...]:
    """Extra DVL noise gamma per axis: sqrt(max(sigma_wave^2 - sigma_calm^2, 0)) (or the total)."""
    if calm is None:
        return run.dvl_std_mps
    return tuple(
        float(np.sqrt(max(w**2 - c**2, 0.0)))
        for w, c in zip(run.dvl_std_mps, calm.dvl_std_mps, strict=True)
    )


CALM_AMPLITUDE_M = 0.01  # a run whose probe shows less than this is the calm reference


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
                    "amplitude_m": run.wave.amplitude_m if run.wave else None,
                    "amplitude_zero_crossing_m": (
                        run.wave.amplitude_zero_crossing_m if run.wave else None
                    ),
                    "frequency_hz": run.wave.frequency_hz if run.wave else None,
                    "dvl_std_mps": list(run.dvl_std_mps),
                    "dvl_extra_std_mps": list(extra),
                    "depth_std_m": run.depth_std_m,
                    "samples": run.dvl_samples,
                }
            )
        return rows


def characterize(logs: list[Log], name: str = "characterized") -> Characterization:
    """Characterize every run; the calmest run below :data:`CALM_AMPLITUDE_M` (or without waves)
    is the calm reference whose noise is subtracted in quadrature; the rest become profile
    conditions at their MEASURED amplitude and frequency."""
    if not logs:
        raise DataError("characterize: no logs given")
    runs = [characterize_run(log) for log in logs]

    def amplitude(run):
        return run.wave.amplitude_m if run.wave else 0.0

    calm_runs = [r for r in runs if amplitude(r) < CALM_AMPLITUDE_M]
    calm = min(calm_runs, key=amplitude) if calm_runs else None
    conditions = [{"name": "calm", "amplitude_m": 0.0, "frequency_hz": None, "dvl_std": [0.0] * 3}]
    for run in runs:
        if run in calm_runs or run.wave is None:
            continue
        conditions.append(
            {
                "name": wave_name(run.wave.amplitude_m, run.wave.frequency_hz),
                "amplitude_m": run.wave.amplitude_m,
                "frequency_hz": run.wave.frequency_hz,
                "dvl_std": list(wave_noise(run, calm)),
            }
        )
    how = "extra noise over the calm run" if calm else "total noise (no calm run given)"
    source = f"undertow characterize: {how}; runs: " + ", ".join(r.source for r in runs)
    profile = NoiseProfile.from_dict({"name": name, "source": source, "conditions": conditions})
    return Characterization(runs, calm, profile)
