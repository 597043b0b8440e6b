"""The physics a wave noise profile follows outside its characterized conditions.

The simulator's DVL (:mod:`undertow.sim.sensors.dvl`) adds to each velocity report a wave term of
standard deviation kappa_j U(d) / sqrt(2) per axis, with U the amplitude of the horizontal
orbital velocity of linear (Airy) waves at the DVL's depth d (Dean & Dalrymple, "Water Wave
Mechanics for Engineers and Scientists", World Scientific 1991, ch. 3-4):

    U(a, f, d, h) = a omega cosh(k (h - d)) / sinh(k h),   omega = 2 pi f,
    omega^2 = g k tanh(k h)                                 (dispersion relation)

in water of depth h (deep water, k h -> inf: U = a omega e^{-k d} with k = omega^2 / g; shallow
water, k h -> 0: U = a sqrt(g / h) at every depth). The extra noise gamma of a profile measured
about a calm run is then proportional to U, so a condition (a, f) outside the profile's is
extrapolated from the nearest characterized condition (a_n, f_n) by the ratio of orbital
velocities, each at its own depth:

    gamma(a, f; d, h) = gamma_n U(a, f, d, h) / U(a_n, f_n, d_0, h_0)

with (d_0, h_0) the DVL and water depth the profile was characterized at and (d, h) those of the
log being localized (:func:`sensor_site`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..io.units import depth_reference
from ..log import G0, Log
from ..sim.waves import depth_factors, wavenumber

# what a condition outside a profile's gets (undertow.estimation.noise): an error, the nearest
# characterized condition as it is, or that condition scaled by the physics below
REFUSE, NEAREST, PHYSICS = "refuse", "nearest", "physics"
OUTSIDE = (REFUSE, NEAREST, PHYSICS)

# The paper gives no depth for its carriage runs. A profile that records none is taken at the
# geometry the simulator builds for the paper's conditions (scenarios wave-a0.10-f1.00 etc.):
# body 0.5 m deep (CarriageModel.depth_m) + the DVL's lever arm 0.284 m (the BlueROV2 URDF of
# Mounting) = 0.784 m, in 3.0 m of water (WaterModel.depth_m, the basin is "about 3 m").
ASSUMED_SENSOR_DEPTH_M = 0.784
ASSUMED_WATER_DEPTH_M = 3.0
ASSUMED_SITE = (
    "assumed: the profile records no depth; the paper's carriage runs as the simulator builds them"
)


@dataclass(frozen=True)
class SensorSite:
    """Where the DVL is: its depth d (m, below the still surface) in water of depth h (m, inf
    for deep water), how each was found, and the spread (10th, 90th percentile) of d over the
    log when it varies."""

    sensor_depth_m: float
    water_depth_m: float
    source: str
    depth_range_m: tuple[float, float] | None = None

    def describe(self) -> str:
        h = "deep water" if math.isinf(self.water_depth_m) else f"h = {self.water_depth_m:.2f} m"
        return f"d = {self.sensor_depth_m:.2f} m, {h}"

    def to_dict(self) -> dict:
        return {
            "sensor_depth_m": float(self.sensor_depth_m),
            "water_depth_m": None if math.isinf(self.water_depth_m) else float(self.water_depth_m),
            "source": self.source,
            "depth_range_m": None if self.depth_range_m is None else list(self.depth_range_m),
        }


def orbital_velocity_amplitude(amplitude_m, frequency_hz, depth_m, water_depth_m,
                               g: float = G0) -> np.ndarray:  # fmt: skip
    """U = a omega cosh(k (h - d)) / sinh(k h) (m/s), k from omega^2 = g k tanh(k h); h = inf is
    deep water (U = a omega e^{-k d}). d is clipped to [0, h]; a = 0 gives 0."""
    a = np.asarray(amplitude_m, float)
    omega = 2.0 * np.pi * np.asarray(frequency_hz, float)
    k = wavenumber(omega, float(water_depth_m), g)
    k_h, _, _ = depth_factors(k, float(water_depth_m), depth_m)
    return a * omega * k_h


def pressure_head_variance(amplitude_m, frequency_hz, depth_m, g: float = G0) -> np.ndarray:
    """a^2 K_p^2 / 2 (m^2): the variance of the depth error a barometer at depth d reads under a
    linear wave of amplitude a and frequency f, the wave's dynamic pressure
    rho g a K_p(d) cos(theta) taken as a depth, K_p = cosh(k (h - d)) / cosh(k h) (Dean &
    Dalrymple, "Water Wave Mechanics for Engineers and Scientists", 1991, ch. 4), in deep water:
    K_p = e^{-k_0 d}, k_0 = omega^2 / g. The deep-water form needs no water depth, so a row's
    value depends on its own depth and time alone. In water of depth h it is below the
    finite-depth K_p by at most 8 % above mid-depth, more near the floor (a third at the floor
    for k_0 h = 1; for larger k_0 h the term vanishes there). Elementwise; d clipped at 0; a = 0,
    or f or d not finite, gives 0."""
    a, f, d = np.broadcast_arrays(*(np.asarray(v, float) for v in (amplitude_m, frequency_hz,
                                                                  depth_m)))  # fmt: skip
    known = (a > 0) & np.isfinite(a) & (f > 0) & np.isfinite(f) & np.isfinite(d)
    k0 = wavenumber(2.0 * np.pi * np.where(known, f, 0.0), math.inf, g)
    _, _, k_p = depth_factors(k0, math.inf, np.where(known, d, 0.0))
    return np.where(known, 0.5 * (a * k_p) ** 2, 0.0)


def sensor_site(log: Log | Iterable[Log], water_density: float | None = None,
                surface_pressure: float | None = None, default: SensorSite | None = None
                ) -> SensorSite | None:  # fmt: skip
    """The DVL's depth and the water depth of ``log``.

    d: the median over the log of the DVL's depth, from the first of: the barometer
    ((p - p_surface) / (rho g); rho and p_surface as given, else the log's metadata
    ``water_density_kg_m3`` and ``surface_pressure_pa``, else fresh water and one standard
    atmosphere), the vehicle's own depth stream, the ground truth's z; each moved from its
    sensor to the DVL by the lever arms taken level (roll and pitch neglected:
    d_DVL = d_baro + t_DVL,z - t_baro,z). The median: one depth for the run's constant condition,
    robust to the barometer's wave and spike excursions.
    h: the log's recorded still-water depth (``metadata["water_depth_m"]``, a simulated log),
    else d + the median DVL altitude, else deep water.
    Without any depth source: ``default`` (the profile's own site) with that said, or None.

    ``log`` may also be the consecutive pieces of one (:func:`undertow.io.iter_log_pieces`;
    only their depth, ground-truth and DVL streams are read): the same site, as the median and
    percentiles are of the same values in another grouping; the finite depths of one source and
    the altitudes are kept, not the pieces."""
    pieces = [log] if isinstance(log, Log) else log
    found: list[list[np.ndarray]] = [[] for _ in DEPTH_SOURCES]
    altitudes: list[np.ndarray] = []
    first = None
    for piece in pieces:
        first = piece if first is None else first
        rho, p0 = depth_reference(piece.metadata, water_density, surface_pressure)
        for k, values in enumerate(_dvl_depths(piece, rho, p0)):
            if values is not None and values.size:
                found[k].append(values)
        best = next((k for k, f in enumerate(found) if f), len(found))
        found[best + 1 :] = [[] for _ in found[best + 1 :]]  # never chosen: not kept
        if piece.dvl is not None and len(piece.dvl):
            altitude = np.asarray(piece.dvl.altitude, float)
            altitudes.append(altitude[np.isfinite(altitude) & (altitude > 0)])
    best = next((k for k, f in enumerate(found) if f), None)
    if best is None:
        if default is None:
            return None
        return SensorSite(default.sensor_depth_m, default.water_depth_m,
                          "DVL depth unknown (no pressure, depth or ground truth): the profile's"
                          )  # fmt: skip
    depth = found[best][0] if len(found[best]) == 1 else np.concatenate(found[best])
    d = float(np.median(depth))
    lo, hi = (float(v) for v in np.percentile(depth, [10, 90]))
    h, h_where = _water_depth(first.metadata, altitudes, d)
    source = f"DVL depth: median of the {DEPTH_SOURCES[best]}; water depth: {h_where}"
    return SensorSite(max(d, 0.0), h, source, (lo, hi))


#: where the DVL's depth is taken from, first found first (:func:`sensor_site`)
DEPTH_SOURCES = ("barometer depth + lever arms", "vehicle's depth stream + lever arms",
                 "ground truth z + lever arm")  # fmt: skip


def _dvl_depths(log: Log, water_density: float, surface_pressure: float) -> list:
    """The finite DVL depths of each of :data:`DEPTH_SOURCES` in ``log`` (None: no such
    stream)."""
    dvl_z = float(log.mounting.dvl.translation[2])
    candidates: list = [None] * len(DEPTH_SOURCES)
    if log.pressure is not None and len(log.pressure):
        baro = log.pressure.depth(water_density, surface_pressure)
        candidates[0] = baro + dvl_z - log.mounting.barometer.translation[2]
    depth_stream = getattr(log, "depth", None)
    if depth_stream is not None and len(depth_stream):
        own = np.asarray(depth_stream.depth, float)
        candidates[1] = own + dvl_z - log.mounting.barometer.translation[2]
    if log.ground_truth is not None and len(log.ground_truth):
        candidates[2] = log.ground_truth.position[:, 2] + dvl_z
    for k, values in enumerate(candidates):
        if values is not None:
            values = np.asarray(values, float)
            candidates[k] = values[np.isfinite(values)]
    return candidates


def _water_depth(metadata: dict, altitudes: list, sensor_depth: float) -> tuple[float, str]:
    recorded = metadata.get("water_depth_m") if isinstance(metadata, dict) else None
    if isinstance(recorded, (int, float)) and math.isfinite(recorded) and recorded > 0:
        return float(recorded), "recorded in the log's metadata"
    if altitudes:
        altitude = np.concatenate(altitudes)
        if altitude.size:
            return sensor_depth + float(np.median(altitude)), "DVL depth + median DVL altitude"
    return math.inf, "unknown (no altitude): deep water assumed"


def assumed_site() -> SensorSite:
    """The site of a profile that records none (:data:`ASSUMED_SENSOR_DEPTH_M`)."""
    return SensorSite(ASSUMED_SENSOR_DEPTH_M, ASSUMED_WATER_DEPTH_M, ASSUMED_SITE)


def scale_by_orbital_velocity(
    node: tuple[str, float, float],
    node_site: SensorSite,
    wave: tuple[float, float],
    site: SensorSite,
) -> tuple[float, dict]:
    """(ratio, record) of the physics extrapolation from the characterized ``node`` (name, a_n,
    f_n) at ``node_site`` (d_0, h_0) to ``wave`` (a, f) at ``site`` (d, h):
    ratio = U(a, f, d, h) / U(a_n, f_n, d_0, h_0). The record holds the law, the node, the
    ratio, both orbital velocities and sites, and a one-line ``statement``. ConfigError when
    the node has no orbital velocity at its site (nothing to scale)."""
    name, a_n, f_n = node
    a, f = wave
    u = float(orbital_velocity_amplitude(a, f, site.sensor_depth_m, site.water_depth_m))
    u_node = float(orbital_velocity_amplitude(a_n, f_n, node_site.sensor_depth_m,
                                              node_site.water_depth_m))  # fmt: skip
    if not (u_node > 0 and math.isfinite(u)):
        raise ConfigError(f"wave a={a:.3g} m, f={f:.3g} Hz: cannot extrapolate from {name}: "
                          f"no orbital velocity there at the profile's {node_site.describe()}"
                          )  # fmt: skip
    ratio = u / u_node
    statement = (
        f"wave a={a:.3g} m, f={f:.2f} Hz is outside the profile's conditions; its noise "
        f"extrapolated by the orbital velocity at the DVL's depth: gamma = gamma({name}) x "
        f"U({site.describe()}) / U({name}, {node_site.describe()}) = x{ratio:.3g} "
        f"({site.source}; profile's depth {node_site.source})"
    )
    return ratio, {
        "law": "gamma = gamma_node U(a, f, d, h) / U(a_node, f_node, d_0, h_0), "
        "U = a omega cosh(k (h - d)) / sinh(k h)",  # fmt: skip
        "from": name,
        "ratio": ratio,
        "orbital_velocity_m_s": u,
        "node_orbital_velocity_m_s": u_node,
        "site": site.to_dict(),
        "profile_site": node_site.to_dict(),
        "statement": statement,
    }


def outside_policy(extrapolate, default: str = PHYSICS) -> str:
    """The policy (one of :data:`OUTSIDE`) an ``extrapolate`` argument names: ``True`` is
    ``"nearest"`` (the old ``--extrapolate``), ``False`` or None the caller's ``default``."""
    if extrapolate is None or extrapolate is False:
        return default
    if extrapolate is True:
        return NEAREST
    if isinstance(extrapolate, str) and extrapolate.strip().lower() in OUTSIDE:
        return extrapolate.strip().lower()
    raise ConfigError(f"extrapolate {extrapolate!r}: expected one of {', '.join(OUTSIDE)}")


def extrapolation_note(noise) -> str | None:
    """One line stating the physics extrapolations a WaveNoise or TrackNoise (``.nodes``) made,
    or None when it made none: the condition's statement, or for a track the count of
    extrapolated nodes and the range of their ratios."""
    nodes = getattr(noise, "nodes", [noise])
    done = [n.extrapolation for n in nodes if getattr(n, "extrapolation", None) is not None]
    if not done:
        return None
    if not hasattr(noise, "nodes"):
        return done[0]["statement"]
    ratios = [e["ratio"] for e in done]
    first = done[0]
    return (
        f"{len(done)} of {len(nodes)} wave track node(s) are outside the profile's conditions; "
        f"their noise extrapolated by the orbital velocity at the DVL's depth: gamma = "
        f"gamma(nearest node) x U / U(node), x{min(ratios):.3g} to x{max(ratios):.3g} "
        f"({first['site']['source']}; profile's depth {first['profile_site']['source']})"
    )


__all__ = [
    "NEAREST",
    "OUTSIDE",
    "PHYSICS",
    "REFUSE",
    "SensorSite",
    "assumed_site",
    "extrapolation_note",
    "orbital_velocity_amplitude",
    "outside_policy",
    "pressure_head_variance",
    "scale_by_orbital_velocity",
    "sensor_site",
]
