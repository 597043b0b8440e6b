"""Signal helpers of the sea-state estimate: centred moving averages, the high-pass
x - MA(MA(x)) that removes the vehicle's own slow motion (in Python and compiled, the fit applies
it to its model too), and the encounter-frequency peaks of the summed periodograms."""

from __future__ import annotations

import numpy as np
from numba import njit

F_LOW_HZ = 0.2  # lowest encounter frequency searched (periods up to 5 s)
#: numba fastmath flags of the compiled loops: no nnan/ninf, the water depth h may be inf
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average of n samples along the last axis (shrinking at the ends)."""
    m = x.shape[-1]
    n = int(max(1, min(n, m)))
    cs = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum(x, axis=-1)], axis=-1)
    i = np.arange(m)
    lo = np.clip(i - n // 2, 0, m)
    hi = np.clip(i - n // 2 + n, 0, m)
    return (cs[..., hi] - cs[..., lo]) / (hi - lo)


@njit(cache=True, fastmath=FASTMATH)
def highpass_inplace(x, n, L, cs, tmp):
    """x[:n] -= MA_L(MA_L(x[:n])) (centred moving averages shrinking at the ends), compiled:
    callable from other kernels; ``cs`` (n + 1) and ``tmp`` (n) are work arrays."""
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


def highpass(x: np.ndarray, n: int) -> np.ndarray:
    """x - MA_n(MA_n(x)): removes the slow motion (gain 1 - sinc^2(f n dt))."""
    y = np.array(x, dtype=float)
    m = y.size
    highpass_inplace(y, m, int(max(1, min(n, m))), np.empty(m + 1), np.empty(m))
    return y


def spectrum_peaks(chans: list, t0: float, t1: float, count: int = 3):
    """Encounter angular frequencies of the highest peaks of the summed, noise-normalized
    periodograms (Hann window, zero padded 2x, parabolic interpolation of log power) of
    ``chans`` (the prepared channels, :class:`.prepare.Channel`, taken as they come so this
    module does not import its caller), and the velocity channels' highest peak-to-median ratio
    near those peaks. Each periodogram is
    weighted by f (half a derivative) so the vehicle's own manoeuvres (turns, speed changes:
    slow, broadband) do not outrank the wave."""
    rate = max(c.rate_hz for c in chans)
    nyq = 0.5 * min(c.rate_hz for c in chans)
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
        y = highpass(c.value, int(round(c.rate_hz / F_LOW_HZ / 2)))
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


def circular_mean(a: np.ndarray) -> float:
    """The direction of the mean unit vector of the angles ``a`` (rad; 0 for none)."""
    return float(np.arctan2(np.sin(a).mean(), np.cos(a).mean())) if a.size else 0.0


__all__ = [
    "F_LOW_HZ",
    "FASTMATH",
    "circular_mean",
    "highpass",
    "highpass_inplace",
    "moving_average",
    "spectrum_peaks",
]
