"""Wave noise profiles: wave condition (amplitude a, frequency f) -> extra measurement noise.

A profile lists characterized conditions with the standard deviation gamma that waves add to
the acoustic measurements (the gamma_DVL of eq:dvl_meas_model per DVL-frame axis, and
optionally gamma_DR of eq:dr_meas_model per angle). The filter adds gamma^2 to R. The profile
shipped with the package, ``noise_profile_paper.yaml``, holds the paper's measured Table I.

Between characterized conditions the std devs are interpolated linearly over a Delaunay
triangulation of the (a, f) nodes (scipy ``LinearNDInterpolator``; each axis scaled by the span
of the nodes first so that metres and hertz weigh alike). A ``calm`` condition (amplitude 0,
``frequency_hz: null``) holds at every frequency: it adds a node at a = 0 for each frequency of
the other conditions, and any a = 0 query returns it. A condition also answers to its canonical
name (``wave-a0.10-f1.00``: a and f to 0.01), so a profile characterized at the measured
a = 0.0999 m serves a query for 0.10 m. When all nodes share one frequency (one characterized
wave plus calm) the interpolation is linear in amplitude at that frequency.

A query outside the nodes gets what the ``extrapolate`` policy says (:data:`OUTSIDE`):

- ``"refuse"`` (:meth:`NoiseProfile.noise`'s default; also ``False``): a :class:`ConfigError`;
- ``"nearest"`` (also ``True``, the CLI's ``--extrapolate``): the nearest node (in the scaled
  (a, f) plane) as it is;
- ``"physics"`` (the Localizer's default): the nearest wave node n scaled by the physics the
  noise follows, the orbital velocity amplitude at the DVL's depth
  (:mod:`~undertow.estimation.noise_physics`):

      gamma(a, f; d, h) = gamma_n U(a, f, d, h) / U(a_n, f_n, d_0, h_0)

  with (d, h) the DVL and water depth of the log (``site``; default the profile's own) and
  (d_0, h_0) those the profile was characterized at (``sensor_depth_m``, ``water_depth_m`` of
  the profile; a profile without them is taken at the paper's carriage geometry, and says so).
  The result's ``how`` is ``"extrapolated"`` and its ``extrapolation`` records the node, the
  ratio, both sites and a one-line statement. Inside the nodes the depth plays no part: the
  profile is used as characterized.

A condition that changes over time (a :class:`~undertow.wavetrack.WaveTrack` of nodes
(t_i, a_i, f_i)) gives :class:`TrackNoise` (:meth:`NoiseProfile.noise_track`): gamma_i =
noise((a_i, f_i)) at each node (calm nodes calm), and at a measurement time t the std devs
interpolated linearly in time between the nodes, held before the first and after the last:

    gamma(t) = gamma_i + (gamma_{i+1} - gamma_i) (t - t_i) / (t_{i+1} - t_i),  t_i <= t <= t_{i+1}
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated

import numpy as np
import yaml
from pydantic import BaseModel, Field

from .._util.atomic import atomic_path
from .._util.validate import read_yaml, validate
from ..errors import ConfigError
from ..wavetrack import WaveTrack
from .noise_physics import (
    PHYSICS,
    REFUSE,
    SensorSite,
    assumed_site,
    outside_policy,
    scale_by_orbital_velocity,
)

_NAME = re.compile(r"^wave-a(\d+(?:\.\d*)?)-f(\d+(?:\.\d*)?)$")


@dataclass(frozen=True)
class WaveCondition:
    """One characterized condition: extra std devs of DVL velocity (m/s, DVL x y z) and of the
    DR angles (rad, roll pitch yaw; zeros when not characterized)."""

    name: str
    amplitude_m: float
    frequency_hz: float | None
    dvl_std: tuple[float, float, float]
    dr_std: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class WaveNoise:
    """The extra noise used for one run (what the Localizer reports in its metadata)."""

    condition: str
    amplitude_m: float
    frequency_hz: float | None
    dvl_std: np.ndarray
    dr_std: np.ndarray
    how: str  # "node", "interpolated", "nearest", "extrapolated" or "calm"
    extrapolation: dict | None = None  # how == "extrapolated": node, ratio, sites, statement

    def to_dict(self) -> dict:
        out = {
            "condition": self.condition,
            "amplitude_m": self.amplitude_m,
            "frequency_hz": self.frequency_hz,
            "dvl_std": [float(v) for v in self.dvl_std],
            "dr_std": [float(v) for v in self.dr_std],
            "how": self.how,
        }
        if self.extrapolation is not None:
            out["extrapolation"] = self.extrapolation
        return out

    def std_at(self, which: str, t: np.ndarray) -> np.ndarray:
        """The std devs of ``which`` ("dvl" or "dr") at the times t: the same (3,) at all."""
        return self.dvl_std if which == "dvl" else self.dr_std

    def wave_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(amplitude m, frequency Hz) of the condition at the times t: the same at all (a 0
        and f NaN when calm)."""
        n = np.asarray(t, float).size
        f = np.nan if self.frequency_hz is None or self.amplitude_m <= 0 else self.frequency_hz
        return np.full(n, float(self.amplitude_m)), np.full(n, float(f))


@dataclass(frozen=True)
class TrackNoise:
    """The extra noise of a wave condition that changes over time: one :class:`WaveNoise` per
    node of ``track``, interpolated linearly in time (held outside the nodes)."""

    track: WaveTrack
    nodes: list[WaveNoise]

    @property
    def condition(self) -> str:
        return f"time-varying ({len(self.nodes)} nodes)"

    def std_at(self, which: str, t: np.ndarray) -> np.ndarray:
        """(len(t), 3) std devs of ``which`` ("dvl" or "dr") at the times t (module doc)."""
        values = np.array([n.dvl_std if which == "dvl" else n.dr_std for n in self.nodes])
        t = np.asarray(t, float)
        return np.stack([np.interp(t, self.track.t, values[:, j]) for j in range(3)], axis=1)

    def wave_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(amplitude m, frequency Hz) at the times t, each interpolated linearly in time between
        the track's nodes (held outside them); a calm node's frequency is its neighbours' (its
        amplitude is 0); f NaN when no node has one."""
        t = np.asarray(t, float)
        track = self.track
        a = np.interp(t, track.t, track.amplitude_m)
        known = np.isfinite(track.frequency_hz)
        if not known.any():
            return a, np.full(t.size, np.nan)
        return a, np.interp(t, track.t[known], track.frequency_hz[known])

    def to_dict(self) -> list[dict]:
        """Per node: its time, condition, std devs and how they were found."""
        return [
            {
                "t": float(ti),
                "condition": n.condition,
                "dvl_std": [float(v) for v in n.dvl_std],
                "dr_std": [float(v) for v in n.dr_std],
                "how": n.how,
                **({} if n.extrapolation is None else {"extrapolation": n.extrapolation}),
            }
            for ti, n in zip(self.track.t, self.nodes, strict=True)
        ]


def _same_condition(c: WaveCondition, name: str, a: float, f: float | None) -> bool:
    """A characterized condition answers a query with its (a, f) or its canonical name (a and f
    to the 0.01 of the name, the precision conditions are characterized and named at)."""
    if c.amplitude_m <= 0 or f is None:
        return False
    exact = abs(c.amplitude_m - a) < 1e-9 and abs(c.frequency_hz - f) < 1e-9
    return exact or wave_name(c.amplitude_m, c.frequency_hz) == name


def _along_amplitude(nodes: np.ndarray, values: np.ndarray, q: np.ndarray):
    """Linear interpolation in amplitude when every node has the query's frequency (a profile
    characterized at one frequency, where a triangulation does not exist); else None."""
    if not np.allclose(nodes[:, 1], q[1], atol=1e-9):
        return None
    order = np.argsort(nodes[:, 0])
    a_nodes = nodes[order, 0]
    if not a_nodes[0] <= q[0] <= a_nodes[-1]:
        return None
    return np.array([np.interp(q[0], a_nodes, values[order, j]) for j in range(values.shape[1])])


def wave_name(amplitude_m: float, frequency_hz: float) -> str:
    """Canonical condition name, e.g. ``wave-a0.10-f1.00``."""
    return f"wave-a{amplitude_m:.2f}-f{frequency_hz:.2f}"


def parse_wave(wave) -> tuple[str, float, float | None]:
    """(name, amplitude, frequency) from ``"calm"``, ``"wave-a0.10-f1.00"``, (a, f) or a mapping
    with ``amplitude_m`` and ``frequency_hz`` (as simulated logs carry in their metadata)."""
    if isinstance(wave, dict) and {"amplitude_m", "frequency_hz"} <= wave.keys():
        wave = (wave["amplitude_m"], wave["frequency_hz"])
    if wave is None or (isinstance(wave, str) and wave.strip().lower() == "calm"):
        return "calm", 0.0, None
    if isinstance(wave, str):
        m = _NAME.match(wave.strip())
        if not m:
            raise ConfigError(f"wave condition {wave!r}: expected 'calm' or like wave-a0.10-f1.00")
        a, f = float(m.group(1)), float(m.group(2))
    else:
        try:
            a, f = (float(v) for v in wave)
        except (TypeError, ValueError) as exc:
            msg = f"wave condition {wave!r}: expected a name or (amplitude, frequency)"
            raise ConfigError(msg) from exc
    if not (math.isfinite(a) and math.isfinite(f) and a >= 0 and f > 0):
        raise ConfigError(f"wave condition {wave!r}: amplitude must be >= 0 and frequency > 0")
    return (wave_name(a, f) if a > 0 else "calm"), a, (f if a > 0 else None)


Std = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class _ConditionFile(BaseModel):
    """One condition of a profile YAML: std devs (>= 0, finite) per axis."""

    name: str | None = None
    amplitude_m: float = Field(ge=0, allow_inf_nan=False)
    frequency_hz: float | None = Field(None, gt=0, allow_inf_nan=False)
    dvl_std: tuple[Std, Std, Std]
    dr_std: tuple[Std, Std, Std] | None = None


class _ProfileFile(BaseModel):
    """What a noise profile YAML holds (``NoiseProfile.to_yaml``, ``undertow characterize``)."""

    name: str | None = ""
    source: str | None = ""
    sensor_depth_m: float | None = Field(None, ge=0, allow_inf_nan=False)
    water_depth_m: float | None = Field(None, gt=0, allow_inf_nan=False)
    conditions: list[_ConditionFile] = Field(min_length=1)


@dataclass
class NoiseProfile:
    """Characterized wave conditions; :meth:`noise` maps a condition to a :class:`WaveNoise`.
    ``sensor_depth_m`` and ``water_depth_m``: the DVL and water depth of the characterization
    (None: not recorded, :meth:`site` assumes the paper's)."""

    conditions: list[WaveCondition]
    name: str = ""
    source: str = ""
    sensor_depth_m: float | None = None
    water_depth_m: float | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def paper(cls) -> NoiseProfile:
        """The paper's Table I (shipped as package data ``noise_profile_paper.yaml``)."""
        text = resources.files("undertow").joinpath("data/noise_profile_paper.yaml").read_text()
        return cls.from_dict(yaml.safe_load(text), origin="noise_profile_paper.yaml")

    @classmethod
    def from_yaml(cls, path: str | Path) -> NoiseProfile:
        data = read_yaml(path, "noise profile")
        return cls.from_dict(data, origin=str(path))

    @classmethod
    def from_dict(cls, data, origin: str = "noise profile") -> NoiseProfile:
        """Check ``data`` against the profile layout (:class:`_ProfileFile`); a missing or invalid
        field is one ConfigError line naming ``origin`` and the field, e.g.
        ``p.yaml: noise profile field conditions.1.dvl_std: Field required``."""
        if not isinstance(data, dict):
            raise ConfigError(
                f"{origin}: not a noise profile (expected a mapping with a `conditions` list, "
                f"got {'an empty file' if data is None else 'a ' + type(data).__name__})"
            )
        checked = validate(_ProfileFile, data, f"{origin}: noise profile field ")
        for i, c in enumerate(checked.conditions):
            if c.amplitude_m > 0 and c.frequency_hz is None:
                raise ConfigError(
                    f"{origin}: noise profile field conditions.{i}.frequency_hz: a wave "
                    "(amplitude_m > 0) needs a frequency"
                )
        conds = [
            WaveCondition(
                name=c.name
                or ("calm" if c.amplitude_m == 0 else wave_name(c.amplitude_m, c.frequency_hz)),
                amplitude_m=c.amplitude_m,
                frequency_hz=c.frequency_hz,
                dvl_std=tuple(c.dvl_std),
                dr_std=tuple(c.dr_std or (0.0, 0.0, 0.0)),
            )
            for c in checked.conditions
        ]
        d, h = checked.sensor_depth_m, checked.water_depth_m
        if d is not None and h is not None and d > h:
            raise ConfigError(f"{origin}: noise profile field sensor_depth_m: {d} m is below the "
                              f"water depth water_depth_m {h} m")  # fmt: skip
        return cls(conds, name=checked.name or "", source=checked.source or "",
                   sensor_depth_m=d, water_depth_m=h)  # fmt: skip

    def to_dict(self) -> dict:
        site = {"sensor_depth_m": self.sensor_depth_m, "water_depth_m": self.water_depth_m}
        return {
            "name": self.name,
            "source": self.source,
            **{k: v for k, v in site.items() if v is not None},
            "conditions": [
                {
                    "name": c.name,
                    "amplitude_m": c.amplitude_m,
                    "frequency_hz": c.frequency_hz,
                    "dvl_std": list(c.dvl_std),
                    "dr_std": list(c.dr_std),
                }
                for c in self.conditions
            ],
        }

    def to_yaml(self, path: str | Path) -> Path:
        """Write the profile as YAML (atomically: temp file, then rename)."""
        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))
        return path

    def site(self) -> SensorSite:
        """Where the profile was characterized: its recorded DVL and water depth, else
        (:func:`~undertow.estimation.noise_physics.assumed_site`) the paper's carriage geometry
        as the simulator builds it (a recorded DVL depth without a water depth: deep water)."""
        if self.sensor_depth_m is None:
            assumed = assumed_site()
            h = self.water_depth_m or assumed.water_depth_m
            return SensorSite(assumed.sensor_depth_m, h, assumed.source)
        h = self.water_depth_m if self.water_depth_m is not None else math.inf
        return SensorSite(self.sensor_depth_m, h, "recorded in the profile")

    def noise(self, wave, extrapolate: bool | str = False,
              site: SensorSite | None = None) -> WaveNoise:  # fmt: skip
        """Extra noise for ``wave`` ("calm", "wave-a0.10-f1.00" or (a, f)); outside the profile's
        conditions as the ``extrapolate`` policy says, ``"physics"`` at ``site`` (the log's DVL
        and water depth; default the profile's own); see the module doc."""
        policy = outside_policy(extrapolate, default=REFUSE)
        name, a, f = parse_wave(wave)
        for c in self.conditions:
            if (a == 0 and c.amplitude_m == 0) or (a > 0 and _same_condition(c, name, a, f)):
                return self._result(name, a, f, c.dvl_std, c.dr_std, "calm" if a == 0 else "node")
        if a == 0:
            return self._result(name, a, f, (0.0,) * 3, (0.0,) * 3, "calm")
        nodes, values, scale = self._nodes()
        q = (np.array([a, f]) - scale[0]) / scale[1]
        v = None
        if len(nodes) >= 3:
            v = self._interp(nodes, values)(q[None, :])[0]
        if v is None or not np.all(np.isfinite(v)):
            v = _along_amplitude(nodes, values, q)
        if v is not None and np.all(np.isfinite(v)):
            return self._result(name, a, f, v[:3], v[3:], "interpolated")
        if policy == REFUSE:
            raise ConfigError(
                f"wave condition {name} is outside the characterized conditions of profile "
                f"{self.name or '?'} (extrapolate='physics' scales the nearest by the orbital "
                "velocity; extrapolate=True, or --extrapolate, uses the nearest as is)"
            )
        if policy == PHYSICS:
            if site is None:
                at = self.site()
                site = SensorSite(at.sensor_depth_m, at.water_depth_m, "DVL depth not given")
            return self._extrapolated(name, a, f, nodes, q, site)
        i = int(np.argmin(np.sum((nodes - q) ** 2, axis=1)))
        return self._result(name, a, f, values[i, :3], values[i, 3:], "nearest")

    def noise_track(self, track: WaveTrack, extrapolate: bool | str = False,
                    site: SensorSite | None = None) -> TrackNoise:  # fmt: skip
        """:class:`TrackNoise` of ``track``: :meth:`noise` at each node with the ``extrapolate``
        policy and ``site`` (a node outside refused: one ConfigError line naming its time)."""
        nodes = []
        for ti, a, f in zip(track.t, track.amplitude_m, track.frequency_hz, strict=True):
            wave = "calm" if a == 0 else (float(a), float(f))
            try:
                nodes.append(self.noise(wave, extrapolate=extrapolate, site=site))
            except ConfigError as exc:
                raise ConfigError(f"wave track node at t = {ti:.3f} s: {exc}") from None
        return TrackNoise(track, nodes)

    def _extrapolated(self, name, a, f, nodes, q, site: SensorSite) -> WaveNoise:
        """The nearest wave node (scaled (a, f) plane) times U(a, f, site) / U(node, profile's
        site): the module doc's physics policy."""
        waves = [c for c in self.conditions if c.amplitude_m > 0]  # _nodes lists them first
        node = waves[int(np.argmin(np.sum((nodes[: len(waves)] - q) ** 2, axis=1)))]
        ratio, record = scale_by_orbital_velocity(
            (node.name, node.amplitude_m, node.frequency_hz), self.site(), (a, f), site
        )
        return WaveNoise(name, a, f, np.array(node.dvl_std, float) * ratio,
                         np.array(node.dr_std, float) * ratio, "extrapolated", record)  # fmt: skip

    def _nodes(self):
        waves = [c for c in self.conditions if c.amplitude_m > 0]
        pts = [(c.amplitude_m, c.frequency_hz) for c in waves]
        vals = [c.dvl_std + c.dr_std for c in waves]
        calm = [c for c in self.conditions if c.amplitude_m == 0]
        if calm:
            for freq in sorted({c.frequency_hz for c in waves}):
                pts.append((0.0, freq))
                vals.append(calm[0].dvl_std + calm[0].dr_std)
        if not pts:
            raise ConfigError(f"noise profile {self.name or '?'} has no wave conditions")
        pts = np.asarray(pts, float)
        lo, span = pts.min(axis=0), np.ptp(pts, axis=0)
        span[span == 0] = 1.0
        return (pts - lo) / span, np.asarray(vals, float), (lo, span)

    def _interp(self, nodes, values):
        if "interp" not in self._cache:
            from scipy.interpolate import LinearNDInterpolator
            from scipy.spatial import QhullError

            try:
                self._cache["interp"] = LinearNDInterpolator(nodes, values, fill_value=np.nan)
            except QhullError:  # collinear nodes: only exact nodes (or nearest) are usable
                self._cache["interp"] = lambda q: np.full((len(q), values.shape[1]), np.nan)
        return self._cache["interp"]

    @staticmethod
    def _result(name, a, f, dvl, dr, how) -> WaveNoise:
        return WaveNoise(name, a, f, np.array(dvl, float), np.array(dr, float), how)
