"""The wave condition over time: what a scenario schedules, a probe measures or the onboard
estimator (:mod:`undertow.seastate`) infers, and what the filter's noise follows.

A :class:`WaveTrack` holds nodes (t_i, a_i, f_i): amplitude a (m, 0 = calm) and frequency f (Hz,
NaN where calm). Between nodes both are linear in time; before the first node and after the
last they are held. The frequency is interpolated over the nodes that have one (a calm node has
none), so a ramp from calm to a wave keeps the wave's frequency while its amplitude grows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError


@dataclass(frozen=True, eq=False)
class WaveTrack:
    """Nodes of the wave condition over time; ``source`` says where it comes from ("scenario",
    "probe", "estimated", "given"); ``direction_deg`` (optional) the world propagation direction
    beta at each node (NaN where unknown)."""

    t: np.ndarray
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    source: str = "given"
    direction_deg: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.atleast_1d(np.asarray(self.t, float))
        a = np.atleast_1d(np.asarray(self.amplitude_m, float))
        f = np.atleast_1d(np.asarray(self.frequency_hz, float))
        if not (t.shape == a.shape == f.shape) or t.ndim != 1 or t.size == 0:
            raise ConfigError("wave track: t, amplitude_m and frequency_hz need the same length")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
            raise ConfigError("wave track: times must be finite and non-decreasing")
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise ConfigError("wave track: amplitudes must be finite and >= 0")
        waves = a > 0
        if np.any(waves & ~(np.isfinite(f) & (f > 0))):
            raise ConfigError("wave track: a node with amplitude > 0 needs a frequency > 0")
        f = np.where(waves, f, np.nan)
        d = None
        if self.direction_deg is not None:
            d = np.atleast_1d(np.asarray(self.direction_deg, float))
            if d.shape != t.shape:
                raise ConfigError("wave track: direction_deg needs one value per node")
        for name, value in (("t", t), ("amplitude_m", a), ("frequency_hz", f),
                            ("direction_deg", d)):  # fmt: skip
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def constant(cls, amplitude_m: float, frequency_hz: float | None, source: str = "given"):
        """One condition for all time (``frequency_hz`` None or NaN when calm)."""
        f = np.nan if frequency_hz is None else float(frequency_hz)
        return cls(np.array([0.0]), np.array([float(amplitude_m)]), np.array([f]), source)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def is_constant(self) -> bool:
        a, f = self.amplitude_m, self.frequency_hz
        same_f = np.all(np.isnan(f)) or np.allclose(f[np.isfinite(f)], np.nanmax(f), rtol=0)
        return bool(np.all(a == a[0]) and same_f)

    def at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """(a, f) at the times ``t`` (arrays of t's shape; f NaN where a = 0)."""
        t = np.asarray(t, float)
        a = np.interp(t, self.t, self.amplitude_m)
        has_f = np.isfinite(self.frequency_hz)
        if has_f.any():
            f = np.interp(t, self.t[has_f], self.frequency_hz[has_f])
        else:
            f = np.full(t.shape, np.nan)
        return a, np.where(a > 0, f, np.nan)

    def to_dict(self) -> dict:
        """Plain lists (NaN frequencies as None), YAML/JSON-safe; :meth:`from_dict` reads it."""

        def plain(v):
            return [None if not np.isfinite(x) else float(x) for x in v]

        out = {
            "source": self.source,
            "t": [float(x) for x in self.t],
            "amplitude_m": [float(x) for x in self.amplitude_m],
            "frequency_hz": plain(self.frequency_hz),
        }
        if self.direction_deg is not None:
            out["direction_deg"] = plain(self.direction_deg)
        return out

    @classmethod
    def from_dict(cls, data: dict, source: str | None = None) -> WaveTrack:
        """A track from :meth:`to_dict`'s layout, or a constant condition written as
        ``{"amplitude_m": a, "frequency_hz": f}`` (scalars)."""
        if not isinstance(data, dict) or not {"amplitude_m", "frequency_hz"} <= data.keys():
            raise ConfigError("wave track: expected amplitude_m and frequency_hz")
        src = source or str(data.get("source", "given"))
        if "t" not in data:
            return cls.constant(_num(data["amplitude_m"]), _num(data["frequency_hz"]), src)
        try:
            d = data.get("direction_deg")
            return cls(
                np.array([_num(v) for v in data["t"]]),
                np.array([_num(v) for v in data["amplitude_m"]]),
                np.array([_num(v) for v in data["frequency_hz"]]),
                src,
                None if d is None else np.array([_num(v) for v in d]),
            )
        except TypeError:
            raise ConfigError("wave track: t, amplitude_m and frequency_hz must be lists") from None


def _num(v) -> float:
    if v is None:
        return float("nan")
    try:
        return float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"wave track: {v!r:.40} is not a number") from None


__all__ = ["WaveTrack"]
