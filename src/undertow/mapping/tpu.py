"""The ``tpu`` mapper's training samples: each hit's total propagated uncertainty (TPU, the
hydrographic term: IHO S-44 6th ed. 2020; Calder and Mayer, "Automatic processing of
high-rate, high-density multibeam echosounder data", G3 4(6) 2003, CUBE) carried into BKI.

A hit m_i = (x_i, y_i, z_i) placed with a pose of position variance (s_x^2, s_y^2, s_z^2)
and a range r_i of standard deviation s_r = s_0 + f r_i (s_0 per sensor: ``range_std_dvl``,
``range_std_sonar``, ``range_std_multibeam``; f = ``range_std_fraction`` for the sonar and the
multibeam, 0 for the DVL) along the beam's unit direction v = (v_x, v_y, v_z) (world, z down)
has the per-axis uncertainty

    sigma_x^2 = s_x^2 + s_b^2 + s_r'^2 v_x^2,   sigma_y^2 = s_y^2 + s_b^2 + s_r'^2 v_y^2,
    sigma_v^2 = s_z^2 + s_r'^2 v_z^2 + s_d^2,     s_r'^2 = s_r^2 + s_w^2.

A range error n moves the hit o + (r + n) v along the beam, by n v: a DVL beam 22.5 deg off
the vertical puts cos^2(22.5 deg) = 85 % of its range variance in depth, a multibeam's outer
beam at 60 deg a quarter (the range's share of a sounding's depth error in the TPU of
multibeam echo sounders: R. Hare, "Depth and position error budgets for multibeam
echosounding", International Hydrographic Review 72(2), 1995).

s_b is a wide beam's footprint: a first return may come from anywhere in a cone of full angle b
(``sonar_beam_width_deg``, the sonar's; the DVL's and the multibeam's beams are narrow, s_b =
s_d = 0), a disk of radius R = r tan(b / 2) whose per-axis standard deviation is R / 2. s_d is
the same beam's shortfall in depth: the first return is the nearest floor in the cone, not the
floor on the axis, so the hit placed on the axis at range r lies above that floor, by r (sec s -
1) on a plane of slope s < b / 2 (the slope error of a wide-beam echo sounder: X. Lurton, "An
Introduction to Underwater Acoustics", 2nd ed. 2010, sec. 8.2; IHO C-13 Manual on Hydrography,
ch. 3). s_d = r (sec(b / 2) - 1), the largest shortfall on a plane, is taken as one standard
deviation: relief steeper than the cone (a step, a rock) falls short by more. It lowers the
hit's weight (below), so where the narrow beams reach a column they decide its depth. s_w is the
waves' share of the range noise (the paper's point: waves corrupt the acoustic measurements):
the RMS vertical orbital displacement between the sensor at depth d and the floor at depth h of
the linear wave of amplitude a and frequency f the trajectory's filter used, s_w = a K_s(d) /
sqrt(2), K_s = sinh(k (h - d)) / sinh(k h), k from omega^2 = g k tanh(k h) (Dean and Dalrymple,
"Water Wave Mechanics for Engineers and Scientists", 1991, ch. 4), h the hit's depth (rounded to
the grid for k). The wave is the settings' ``wave``, else the one the trajectory's filter used
(:func:`with_wave`).

**Across the floor** (x, y) the hit's kernel is the sparse kernel of ``eq:kernel`` at the
length scale whose standard deviation is the hit's: the kernel k(d; l) has standard
deviation c l, c = sqrt(1/6 - 1/pi^2) = 0.2556 (second moment int d^2 k / int k, in closed
form), so

    l_j = min(max(l_0, sigma_j / c), l_cap),    j = x, y,

l_0 the kernel of a perfectly placed hit (``base_length``), l_cap the largest support
(``max_length``, which bounds the cost and the tiles' halo). The kernel is normalized to
the mass of the base kernel, k_i = sigma_0 (l_0 / l_x)(l_0 / l_y) k(|d_x|; l_x) k(|d_y|;
l_y), so a hit spread by its pose uncertainty carries the evidence of one hit spread over
where it may lie (the convolution of the base kernel with the pose's density keeps its
mass), not more evidence: the paper's adaptive kernel widens without lowering its peak,
which adds mass where the pose is worst. Each hit is also weighted by its vertical
precision relative to a perfectly placed one, s_r^2 / sigma_v^2 (inverse-variance
weighting, as CUBE weights soundings), s_rz^2 / sigma_v^2 with s_rz = s_r' |v_z| the depth
share of the sensor's noise in these waves: what lowers it is the pose's vertical
uncertainty.

**Along the vertical** the hit's mass goes to the three cells around it with weights that
keep its depth and its vertical variance exactly: with z_c the nearest cell centre, u =
(z_i - z_c) / r in [-1/2, 1/2] (r the resolution) and v = |u| (1 - |u|) + sigma_v^2 / r^2
(the least variance a distribution on the cells can have with mean u, plus the hit's),
the cells z_c - r, z_c, z_c + r get

    w_- = (u^2 + v - u) / 2,   w_0 = 1 - u^2 - v,   w_+ = (u^2 + v + u) / 2

(sum 1, mean u r, variance v r^2). v is capped at 1 - u^2 (w_0 >= 0): a vertical standard
deviation above about 0.7 r is more than three cells can hold and is cut to it.

Free samples (label 0) keep the base kernel (l_0 across, r / 2 along the vertical: their own
cell and column) and weight sigma_0: they clear the water the beam crossed.

The surface that reads this map back (depth and standard deviation per column) is
:func:`undertow.mapping.surface.evidence_surface`.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import njit

from ..errors import ConfigError
from ..sim.waves import wavenumber_array
from ..wavetrack import WaveTrack
from .depth_wave import depth_wave_terms, swell_variances, trajectory_depth_noise
from .samples import SENSOR_SONAR, Samples

#: standard deviation of the sparse kernel k(d; l) in units of l: sqrt(1/6 - 1/pi^2)
KERNEL_STD = math.sqrt(1.0 / 6.0 - 1.0 / math.pi**2)


def trajectory_wave(trajectory) -> tuple[float, float] | None:
    """(amplitude m, frequency Hz) of the waves the trajectory's filter used (its metadata's
    ``wave_track``: the RMS amplitude and the median frequency; else ``wave_noise``), or None
    (calm, or a trajectory that does not say)."""
    meta = getattr(trajectory, "metadata", None) or {}
    track = meta.get("wave_track")
    if isinstance(track, dict) and len(track.get("amplitude_m", ())):
        wave = _track_wave(track)
        if wave is not None:
            return wave
    noise = meta.get("wave_noise")
    if isinstance(noise, dict):
        a, f = noise.get("amplitude_m"), noise.get("frequency_hz")
        if a is not None and f is not None and np.isfinite([a, f]).all() and a > 0 and f > 0:
            return float(a), float(f)
    return None


def log_wave(log) -> tuple[float, float] | None:
    """(amplitude m, frequency Hz) of the waves ``log`` records (its metadata's ``wave``, as
    ``undertow localize`` reads it when no condition is given: a condition or a track,
    :meth:`~undertow.wavetrack.WaveTrack.from_dict`, reduced as :func:`trajectory_wave` reduces
    a track), or None (calm, none recorded, or a record that is no wave track)."""
    try:
        track = WaveTrack.from_dict((getattr(log, "metadata", None) or {}).get("wave"))
    except ConfigError:
        return None
    return _track_wave({"amplitude_m": track.amplitude_m, "frequency_hz": track.frequency_hz})


def _track_wave(track: dict) -> tuple[float, float] | None:
    """(RMS amplitude, median frequency) of a track's nodes; None when calm or unknown."""
    a = np.asarray(track["amplitude_m"], float)
    f = np.asarray(track.get("frequency_hz", ()), float)
    a, f = a[np.isfinite(a)], f[np.isfinite(f) & (f > 0)]
    if a.size and f.size and np.sqrt(np.mean(a * a)) > 0:
        return float(np.sqrt(np.mean(a * a))), float(np.median(f))
    return None


def with_wave(config, trajectory, log=None):
    """``config`` with its ``wave`` and ``depth_noise`` resolved for the ``tpu`` mapper: as
    given, else the wave the trajectory's filter used (:func:`trajectory_wave`), else the one
    ``log`` records (:func:`log_wave`: a trajectory made elsewhere says none; stated in one
    warning), when the mapper adds the wave's range noise or the swell in the depth
    (``wave_range_noise``, ``wave_depth_noise``), and the depth measurements the filter fused
    (:func:`~undertow.mapping.depth_wave.trajectory_depth_noise`) for the latter. Other
    methods unchanged; what neither says stays None. Resolved once per map, so tiles and the
    whole agree."""
    if config.method != "tpu":
        return config
    update = {}
    if config.wave is None and (config.wave_range_noise or config.wave_depth_noise):
        wave = trajectory_wave(trajectory)
        if wave is None and log is not None:
            wave = log_wave(log)
            if wave is not None:
                warnings.warn(f"map: the waves the log records (a = {wave[0]:.3g} m, f = "
                              f"{wave[1]:.3g} Hz) add their range noise; the trajectory says "
                              "none (mapping: {wave: [A, F]} sets them)", RuntimeWarning,
                              stacklevel=2)  # fmt: skip
        if wave is not None:
            update["wave"] = wave
    if config.wave_depth_noise and config.depth_noise is None:
        noise = trajectory_depth_noise(trajectory)
        if noise is not None:
            update["depth_noise"] = noise
    return config.model_copy(update=update) if update else config


def depth_wave_of(config):
    """(a, f, std, interval) of the swell in the depth the ``config`` (resolved by
    :func:`with_wave`) adds, or None."""
    if not config.wave_depth_noise or config.wave is None or config.depth_noise is None:
        return None
    return (*config.wave, *config.depth_noise)


def wave_range_std(hits: Samples, rows, wave, resolution: float) -> np.ndarray:
    """s_w of the samples ``rows`` of ``hits`` (:func:`wave_std` of their sensor and end point
    depths); zeros without a wave or where the ray is unknown."""
    out = np.zeros(len(rows))
    ray = hits.ray[rows]
    known = ray >= 0
    if wave is None or not known.any() or not len(hits.origins):
        return out
    out[known] = wave_std(hits.origins[ray[known], 2], hits.points[rows[known], 2], wave,
                          resolution)  # fmt: skip
    return out


def wave_std(d, z, wave, resolution: float) -> np.ndarray:
    """s_w = a K_s(d) / sqrt(2) (module doc) of hits at depth z seen from a sensor at depth d:
    the water depth h is z rounded to the grid's ``resolution`` (for the wavenumber, so a
    hit's value does not depend on the others: tiles map alike); zeros without a wave."""
    d, z = np.asarray(d, float), np.asarray(z, float)
    if wave is None or not z.size:
        return np.zeros(z.size)
    e_1, e_2, m = wave_exponentials(d, z, wave[1], resolution)
    # K_s = sinh(k (h - d)) / sinh(k h) as a ratio of exponentials (no overflow when deep)
    return wave[0] * np.nan_to_num((e_1 - e_2) / -m) / np.sqrt(2.0)


def wave_exponentials(d, z, frequency: float, resolution: float):
    """(exp(-k d), exp(-k (2 h - d)), expm1(-2 k h)) of :func:`wave_std` (d clipped to [0, h])."""
    h = np.maximum(np.round(z / resolution) * resolution, resolution)
    depths, index = np.unique(h, return_inverse=True)
    k = wavenumbers(2.0 * np.pi * frequency, depths)[index]
    d = np.clip(d, 0.0, h)
    return np.exp(-k * d), np.exp(-k * (2.0 * h - d)), np.expm1(-2.0 * k * h)


def swell_depth_variance(hits: Samples, rows, var_z, depth_wave, resolution: float):
    """The swell's share of the pose's depth variance of the samples ``rows`` of ``hits``
    (:mod:`undertow.mapping.depth_wave`, K_p = cosh(k (h - d)) / cosh(k h) at the sensor's
    depth d); zeros without ``depth_wave`` (a, f, std, interval) or where the ray is unknown."""
    out = np.zeros(len(rows))
    ray = hits.ray[rows]
    known = ray >= 0
    if depth_wave is None or not known.any() or not len(hits.origins):
        return out
    e_1, e_2, m = wave_exponentials(hits.origins[ray[known], 2], hits.points[rows[known], 2],
                                    depth_wave[1], resolution)  # fmt: skip
    var = np.ascontiguousarray(var_z[known], dtype=float)
    out[known] = swell_variances(var, (e_1 + e_2) / (2.0 + m), *depth_wave_terms(depth_wave))
    return out


@njit(cache=True)
def wavenumbers(omega, depths):
    """:func:`~undertow.sim.waves.wavenumber` of one omega in each of ``depths`` (g the
    standard gravity, its default), in one compiled loop."""
    w = np.array([omega])
    out = np.empty(depths.size)
    for i in range(depths.size):
        out[i] = wavenumber_array(w, depths[i], 9.80665)[0]
    return out


def hit_sigmas(samples: Samples, range_std, range_std_fraction: float,
               sonar_beam_width_deg: float = 0.0, wave=None, resolution: float = 0.1,
               depth_wave=None):  # fmt: skip
    """(sigma_x, sigma_y, sigma_v, s_rz, r_s^2) of every hit of ``samples`` (label 1, in order;
    the free samples need none; module doc): the horizontal standard deviations (pose,
    footprint and the range noise's horizontal share), the vertical one, the depth share
    s_rz = s_r' |v_z| of the range noise in these waves (v the beam's direction, o to the hit;
    vertical for a hit of unknown ray), and the squared range of a sonar's hit (0 for the
    others). ``range_std``: s_0 of
    the DVL, the sonar and the multibeam (by ``Samples.sensor``; a sample of unknown sensor
    takes the largest); ``wave``: (amplitude, frequency) or None; ``depth_wave``: (a, f, std,
    interval) of the swell in the pose's depth (:mod:`undertow.mapping.depth_wave`) or None."""
    rows = np.flatnonzero(samples.label > 0.5)
    var = samples.pose_variance[rows]
    ray = samples.ray[rows]
    rng = np.zeros(len(rows))
    known = (ray >= 0) & (len(samples.origins) > 0)
    along = np.zeros((len(rows), 3))  # (v_x^2, v_y^2, v_z^2) of the beam; v_z^2 = 1 unknown
    along[:, 2] = 1.0
    if known.any():
        d = samples.points[rows[known]] - samples.origins[ray[known]]
        rng[known] = np.linalg.norm(d, axis=1)
        r2 = rng[known] * rng[known]
        beam = r2 > 0
        along[np.flatnonzero(known)[beam]] = d[beam] * d[beam] / r2[beam, None]
    s0 = np.asarray(range_std, float)
    fraction = np.array([0.0, range_std_fraction, range_std_fraction])
    sensor = samples.sensor[rows].astype(np.int64)
    sensor = np.where((sensor >= 0) & (sensor < 3), sensor, int(np.argmax(s0)))
    s_w = wave_range_std(samples, rows, wave, resolution)
    s_range = np.hypot(s0[sensor] + fraction[sensor] * rng, s_w)
    s_r = s_range * np.sqrt(along[:, 2])
    half = np.deg2rad(sonar_beam_width_deg) / 2.0
    tan_half = np.tan(half)
    sonar = sensor == SENSOR_SONAR
    s_b2 = np.where(sonar, (rng * tan_half / 2.0) ** 2, 0.0)
    s_d2 = np.where(sonar, shortfall(rng, tan_half) ** 2, 0.0)
    var_z = var[:, 2] + swell_depth_variance(samples, rows, var[:, 2], depth_wave, resolution)
    s_range2 = s_range * s_range
    return (np.sqrt(var[:, 0] + s_b2 + s_range2 * along[:, 0]),
            np.sqrt(var[:, 1] + s_b2 + s_range2 * along[:, 1]),
            np.sqrt(var_z + s_r**2 + s_d2), s_r, np.where(sonar, rng * rng, 0.0))  # fmt: skip


def shortfall(r, tan_half):
    """A wide beam's shortfall s_d = r (sec(b / 2) - 1) at range r, tan_half = tan(b / 2)
    (module doc)."""
    return r * (np.sqrt(1.0 + tan_half * tan_half) - 1.0)


def lattice_spread(z, sigma_v, resolution: float):
    """(z_c, u, v) of the lattice (module doc): the nearest cell centre z_c to each depth z,
    its offset u = (z - z_c) / r in cells and the variance v (in cells^2) of the three cells'
    weights about z, |u| (1 - |u|) + sigma_v^2 / r^2 capped at 1 - u^2."""
    r = float(resolution)
    z = np.asarray(z, float)
    zc = (np.floor(z / r) + 0.5) * r
    u = (z - zc) / r
    au = np.abs(u)
    v = np.minimum(au * (1.0 - au) + (np.asarray(sigma_v, float) / r) ** 2, 1.0 - u * u)
    return zc, u, v


def lattice_weights(z, sigma_v, resolution: float):
    """(centres (n, 3), weights (n, 3)): the three cell centres around each depth z (z_c - r,
    z_c, z_c + r) and the weights that keep its mean z and variance sigma_v^2 plus the
    least the cells can hold (module doc; :func:`lattice_spread`)."""
    zc, u, v = lattice_spread(z, sigma_v, resolution)
    w_minus = np.maximum((u * u + v - u) / 2.0, 0.0)
    w_plus = np.maximum((u * u + v + u) / 2.0, 0.0)
    w_zero = np.maximum(1.0 - w_minus - w_plus, 0.0)
    centres = zc[:, None] + float(resolution) * np.array([-1.0, 0.0, 1.0])
    return centres, np.stack([w_minus, w_zero, w_plus], axis=1)


def tpu_hit_weights(samples: Samples, *, resolution: float, base_length: float,
                    max_length: float, range_std, range_std_fraction: float,
                    sonar_beam_width_deg: float = 0.0, wave=None, depth_wave=None):  # fmt: skip
    """Per hit of ``samples`` (label 1, in order; module doc): (x, y, l_x, l_y, weight
    sigma_0 (l_0 / l_x) (l_0 / l_y) s_rz^2 / sigma_v^2, sigma_v^2, parts (n, 5): sigma_x^2,
    sigma_y^2, s_rz^2, r_s^2 and the lattice's v r^2, as
    :data:`~undertow.mapping.tpuscatter.HIT_PARTS`)."""
    sx, sy, sv, s_r, r2 = hit_sigmas(samples, range_std, range_std_fraction, sonar_beam_width_deg,
                                     wave, resolution, depth_wave)  # fmt: skip
    hit = samples.label > 0.5
    lx = np.clip(sx / KERNEL_STD, base_length, max_length)
    ly = np.clip(sy / KERNEL_STD, base_length, max_length)
    precision = np.divide(s_r * s_r, sv * sv, out=np.ones_like(sv), where=sv > 0)
    weight = samples.sigma0[hit] * (base_length / lx) * (base_length / ly) * precision
    points = samples.points[hit]
    lattice = lattice_spread(points[:, 2], sv, resolution)[2] * resolution**2
    parts = np.stack([sx * sx, sy * sy, s_r * s_r, r2, lattice], axis=1)
    return points[:, 0], points[:, 1], lx, ly, weight, sv * sv, parts


def tpu_training(samples: Samples, hits=None, **settings):
    """The samples the ``tpu`` mapper scatters with the product kernel, and their per-axis
    length scales: (points (M, 3), label (M,), weight (M,), lengths (M, 3)). Free samples
    first, in order, then every hit's three vertical cells (module doc). ``settings``: those
    of :func:`tpu_hit_weights`; ``hits``: its result when already computed."""
    if hits is None:
        hits = tpu_hit_weights(samples, **settings)
    _, _, lx, ly, weight, var_v, _ = hits
    resolution, base_length = settings["resolution"], settings["base_length"]
    sv = np.sqrt(var_v)
    hit = samples.label > 0.5
    free = ~hit
    lengths_free = np.tile([base_length, base_length, resolution / 2], (int(free.sum()), 1))
    centres, w = lattice_weights(samples.points[hit, 2], sv, resolution)
    pts_hit = np.repeat(samples.points[hit], 3, axis=0)
    pts_hit[:, 2] = centres.reshape(-1)
    lengths_hit = np.repeat(np.stack([lx, ly, np.full(len(lx), resolution / 2)], 1), 3, axis=0)
    weight_hit = (weight[:, None] * w).reshape(-1)
    keep = weight_hit > 0
    points = np.concatenate([samples.points[free], pts_hit[keep]])
    label = np.concatenate([samples.label[free], np.ones(int(keep.sum()))])
    weights = np.concatenate([samples.sigma0[free], weight_hit[keep]])
    lengths = np.concatenate([lengths_free, lengths_hit[keep]])
    return points, label, weights, lengths
