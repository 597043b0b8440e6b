"""Mappers: counting sensor model (CSM), BKI with the sparse kernel, the paper's adaptive BKI and
``tpu``, BKI with each hit's total propagated uncertainty (the default for users).

All four share one verb, :meth:`Mapper.integrate`, and accumulate the posterior concentration
parameters of ``eq:alpha_param`` / ``eq:beta_param``:

    alpha_* = alpha_0 + sum_i k(m_*, m_i) y_i,    beta_* = beta_0 + sum_i k(m_*, m_i)(1 - y_i)

- ``csm``: k = 1 if m_i lies in the cell of m_*, else 0 (per-cell counts; the paper's baseline).
  The sensor weight sigma_0 is not used: CSM counts.
- ``bki``: k of ``eq:kernel`` with d = ||m_* - m_i|| and one isotropic length scale l.
- ``adaptive``: ``eq:decom_kernel`` / ``eq:new_conc_params_alpha``: k = sigma_0 prod_j k_j(|d_j|)
  (sigma_0 applied once), with per-sample length scales from ``eq:lengthscale_1``:
  l_j = s~_j^2 (l_max_j - l_min_j) + l_min_j, s~_j^2 = (s_j^2 - s_min_j^2) / (s_max_j^2 - s_min_j^2)
  clipped to [0, 1]. With ``variance_bounds=None`` ("session" normalization) the min/max are
  taken over the samples of each :meth:`integrate` call, so integrate a whole session at once to
  follow the paper; with fixed ``variance_bounds=(min(3,), max(3,))`` the mapper can run
  incrementally (online). Where max == min on an axis, s~ = 0 there, i.e. l_min is used.
- ``tpu``: the product kernel with each hit's own length scales from its pose's standard
  deviation (not normalized over the session), its mass kept and its vertical placement exact
  (:mod:`undertow.mapping.tpu`; samples kept as rays scattered straight from them,
  :mod:`undertow.mapping.tpuscatter`).

The kernel is evaluated at cell centres; sums are scattered into a sparse chunked grid by numba
kernels (see :mod:`undertow.mapping.kernels`).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError
from ..occupancy import OccupancyMap
from .columns import ColumnGrid
from .config import MappingConfig, Method
from .grid import ChunkedGrid, points_extent
from .kernels import MODE_CELL, MODE_PRODUCT, MODE_RADIAL
from .rayscatter import ray_extent
from .samples import SENSOR_SONAR, RaySamples, Samples
from .tpu import depth_wave_of, tpu_hit_weights, tpu_training
from .tpuscatter import tpu_extent, tpu_hits

DEFAULT_MEMORY_GB = 8.0  # when the machine's RAM cannot be read


@functools.cache
def default_max_memory_gb() -> float:
    """Half the machine's physical RAM, in GB (8 GB where it cannot be read), and at most half
    the process's address-space limit (``ulimit -v``) when one is set."""
    try:
        limit = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 / 1e9
    except (AttributeError, ValueError, OSError):
        limit = DEFAULT_MEMORY_GB
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            limit = min(limit, soft / 2 / 1e9)
    except (ImportError, ValueError, OSError):
        pass
    return limit


class Mapper:
    """Base: a chunked grid of evidence mass plus the Beta prior (alpha_0, beta_0).

    Arguments are checked values (see :class:`~undertow.mapping.config.MappingConfig`, which
    checks them and holds the defaults; :func:`make_mapper` builds a mapper through it).
    ``max_memory_gb`` caps the storage one :meth:`integrate` may need (estimated first; None:
    half the machine's RAM)."""

    method = ""

    def __init__(self, *, resolution: float, alpha0: float, beta0: float,
                 max_memory_gb: float | None,
                 resident_mb: float | None = None) -> None:  # fmt: skip
        self.resolution, self.alpha0, self.beta0 = float(resolution), float(alpha0), float(beta0)
        self.max_memory_gb = max_memory_gb
        resident = None if resident_mb is None else resident_mb * 1e6
        self.grid = ChunkedGrid(self.resolution, resident_bytes=resident)
        self.n_samples = 0
        self.n_integrations = 0
        self.seeded_from = ""

    def integrate(self, samples: Samples) -> None:
        """Add the samples' kernel-weighted labels to alpha and beta (callable repeatedly)."""
        if not isinstance(samples, Samples):
            raise DataError(f"integrate() needs Samples, got {type(samples).__name__}")
        if len(samples):
            self._scatter(samples)
        self.n_samples += len(samples)
        self.n_integrations += 1

    def _scatter(self, samples: Samples) -> None:
        raise NotImplementedError

    def _grid_scatter(self, mode, samples: Samples, bounds, l_min, l_max) -> None:
        """Refuse (one line) when the storage the samples need exceeds ``max_memory_gb``,
        then scatter; running out of memory anyway is the same one line, not a traceback.
        Samples kept as rays (:class:`~undertow.mapping.samples.RaySamples`) are scattered
        straight from the rays in product mode (the same map bit for bit, faster)."""
        limit_gb = self.max_memory_gb or default_max_memory_gb()
        rays = samples.rays if mode == MODE_PRODUCT and isinstance(samples, RaySamples) else None
        if rays is None:
            extent = points_extent(samples.points)  # non-empty: integrate() skips empty samples
            need = None
        else:
            extent = ray_extent(rays.origin, rays.direction, rays.r, rays.rows, rays.f)
            need = self.grid.bound_bytes(mode, len(samples), l_min, l_max, limit_gb * 1e9, extent)
        if need is None:  # the written samples (when a bound does not settle it: counted)
            need = self.grid.estimate_bytes(mode, samples.points, samples.pose_variance, bounds,
                                            l_min, l_max, limit_gb * 1e9, extent)  # fmt: skip
        self._check_need(need, len(samples), limit_gb)
        try:
            if rays is None:
                self.grid.scatter(mode, samples.points, samples.label, samples.sigma0,
                                  samples.pose_variance, bounds, l_min, l_max, extent)  # fmt: skip
            else:
                self.grid.scatter_rays(rays, bounds, l_min, l_max, extent)
        except MemoryError:
            raise out_of_memory(self.resolution) from None

    def _check_need(self, need: float, n: int, limit_gb: float) -> None:
        """The one-line refusal when the estimated storage ``need`` exceeds the limit."""
        if need > limit_gb * 1e9:
            raise ConfigError(
                f"mapping {n} samples at resolution {self.resolution:g} m would need "
                f"an estimated {need / 1e9:.3g} GB or more (limit {limit_gb:.3g} GB, "
                "mapping.max_memory_gb): use a coarser resolution or raise the limit"
            )

    def seed(self, prior: OccupancyMap | str | Path) -> OccupancyMap:
        """Add a saved map's evidence (alpha - alpha_0, beta - beta_0 per cell) to this map;
        returns the prior map."""
        if not isinstance(prior, OccupancyMap):
            self.seeded_from = str(prior)
            prior = OccupancyMap.load(prior)
        if not np.isclose(prior.resolution, self.resolution):
            raise ConfigError(
                f"prior map resolution {prior.resolution} m differs from {self.resolution} m"
            )
        self.grid.add_mass(prior.cells, prior.alpha - prior.alpha0, prior.beta - prior.beta0)
        return prior

    def metadata(self) -> dict:
        """Parameters and bookkeeping, stored with the map."""
        return {
            "method": self.method, "resolution": self.resolution, "alpha0": self.alpha0,
            "beta0": self.beta0, "n_samples": self.n_samples,
            "n_integrations": self.n_integrations, "seeded_from": self.seeded_from,
        }  # fmt: skip

    def occupancy(self) -> OccupancyMap:
        """Posterior per cell that received kernel mass (``eq:mean_var`` via OccupancyMap)."""
        try:
            cells, a, b = self.grid.cells()
        except MemoryError:
            raise out_of_memory(self.resolution) from None
        return OccupancyMap(cells, self.alpha0 + a, self.beta0 + b, self.resolution,
                            self.alpha0, self.beta0, self.metadata(),
                            self.column_stats())  # fmt: skip

    def column_stats(self):
        """The map's :class:`~undertow.occupancy.ColumnStats`; None: the mapper keeps none."""
        return None


class CsmMapper(Mapper):
    """Counting sensor model: hits add 1 to alpha, free samples add 1 to beta, in their cell."""

    method = "csm"

    def _scatter(self, samples: Samples) -> None:
        zero = np.zeros(3)
        self._grid_scatter(MODE_CELL, samples, (zero, zero), zero, zero)


class BkiMapper(Mapper):
    """BKI with the isotropic sparse kernel of ``eq:kernel`` (one length scale l)."""

    method = "bki"

    def __init__(self, *, length_scale: float, **base) -> None:
        super().__init__(**base)
        self.length_scale = float(length_scale)

    def _scatter(self, samples: Samples) -> None:
        l, zero = np.full(3, self.length_scale), np.zeros(3)
        self._grid_scatter(MODE_RADIAL, samples, (zero, zero), l, l)

    def metadata(self) -> dict:
        return {**super().metadata(), "length_scale": self.length_scale}


class AdaptiveBkiMapper(Mapper):
    """The paper's adaptive BKI: product kernel with pose-variance length scales (module doc).
    ``variance_bounds`` None: per-session normalization, else fixed (min(3,), max(3,))."""

    method = "adaptive"

    def __init__(self, *, l_min, l_max, variance_bounds, **base) -> None:
        super().__init__(**base)
        self.l_min = np.asarray(l_min, float)
        self.l_max = np.asarray(l_max, float)
        self.normalization = "session" if variance_bounds is None else "fixed"
        self.variance_bounds = (
            None
            if variance_bounds is None
            else tuple(np.asarray(v, float) for v in variance_bounds)
        )
        self.last_variance_bounds = self.variance_bounds

    def _bounds(self, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s_min^2, s_max^2) per axis: over the given samples (session) or the fixed bounds."""
        if self.variance_bounds is None:
            return var.min(axis=0), var.max(axis=0)
        return self.variance_bounds

    def length_scales(self, pose_variance) -> np.ndarray:
        """``eq:lengthscale_1`` per sample and axis, (N, 3) (the scatter kernel computes the
        same inline; this is for inspection)."""
        var = np.asarray(pose_variance, float).reshape(-1, 3)
        lo, hi = self._bounds(var)
        span = hi - lo
        safe = np.where(span > 0, span, 1.0)
        s2 = np.where(span > 0, np.clip((var - lo) / safe, 0.0, 1.0), 0.0)
        return s2 * (self.l_max - self.l_min) + self.l_min

    def _scatter(self, samples: Samples) -> None:
        # every ray has a sample (its hit): the rays' variances are the samples' min and max
        rays = samples.rays if isinstance(samples, RaySamples) else None
        bounds = self._bounds(samples.pose_variance if rays is None else rays.var)
        self.last_variance_bounds = bounds
        self._grid_scatter(MODE_PRODUCT, samples, bounds, self.l_min, self.l_max)

    def metadata(self) -> dict:
        bounds = self.last_variance_bounds
        return {
            **super().metadata(), "l_min": self.l_min.tolist(), "l_max": self.l_max.tolist(),
            "normalization": self.normalization,
            "variance_bounds": None if bounds is None else [np.asarray(b).tolist() for b in bounds],
        }  # fmt: skip


class TpuBkiMapper(Mapper):
    """BKI with each hit's total propagated uncertainty (:mod:`undertow.mapping.tpu`): the
    kernel spread across the floor by the pose's horizontal standard deviation with its mass
    kept, the hit weighted by its vertical precision and placed on the vertical with its depth
    and variance kept. The default mapper; its surface is
    :func:`~undertow.mapping.surface.evidence_surface`."""

    method = "tpu"

    def __init__(self, *, base_length, max_length, range_std, range_std_fraction,
                 sonar_beam_width_deg, wave=None, depth_wave=None, sonar_carve=True,
                 **base) -> None:  # fmt: skip
        super().__init__(**base)
        self.sonar_beam_width_deg = float(sonar_beam_width_deg)
        #: whether the sonar's first returns carve their cones free (:mod:`~undertow.mapping.carve`)
        self.sonar_carve = bool(sonar_carve)
        #: (amplitude m, frequency Hz) of the waves whose orbital motion adds to the range
        #: noise (the settings' ``wave``, resolved by :func:`~undertow.mapping.tpu.with_wave`)
        self.wave = wave
        #: (a m, f Hz, std m, interval s) of the swell in the poses' depth
        #: (:mod:`~undertow.mapping.depth_wave`; :func:`~undertow.mapping.tpu.depth_wave_of`)
        self.depth_wave = None if depth_wave is None else tuple(float(v) for v in depth_wave)
        self.base_length, self.max_length = float(base_length), float(max_length)
        self.range_std = tuple(float(v) for v in range_std)  # DVL, sonar, multibeam
        self.range_std_fraction = float(range_std_fraction)
        #: the hits' uncertainties per column (:mod:`~undertow.mapping.columns`)
        self.columns = ColumnGrid(self.resolution, self.grid.resident_bytes)

    def _settings(self) -> dict:
        return {"resolution": self.resolution, "base_length": self.base_length,
                "max_length": self.max_length, "range_std": self.range_std,
                "range_std_fraction": self.range_std_fraction,
                "sonar_beam_width_deg": self.sonar_beam_width_deg, "wave": self.wave,
                "depth_wave": self.depth_wave}  # fmt: skip

    def _scatter(self, samples: Samples) -> None:
        """Samples kept as rays are scattered straight from them
        (:mod:`~undertow.mapping.tpuscatter`, the same map bit for bit) unless only counting
        their chunks can settle the memory estimate; the others by :meth:`_scatter_written`."""
        if isinstance(samples, RaySamples):
            rays = samples.rays
            hits = tpu_hits(rays, **self._settings())
            lo, hi, finite, n = tpu_extent(rays.origin, rays.direction, rays.rows, rays.f,
                                           hits.x, hits.y, hits.z, hits.w)  # fmt: skip
            if n == 0:
                return
            cap = max(self.max_length, self.resolution / 2)
            limit_gb = self.max_memory_gb or default_max_memory_gb()
            need = self.grid.bound_bytes(MODE_PRODUCT, n, (0.0, 0.0, 0.0), (cap, cap, cap),
                                         limit_gb * 1e9, (lo, hi, finite))  # fmt: skip
            if need is not None:
                self._check_need(need, n, limit_gb)
                try:
                    self.grid.scatter_tpu(rays, hits, cap, (lo, hi, finite), n)
                    self.columns.add_hits(hits, (lo, hi, finite))
                    sonar = rays.sensor == SENSOR_SONAR
                    if sonar.any():  # (most pings have none: skip the masks)
                        self._carve(rays.origin[sonar], rays.direction[sonar], rays.r[sonar],
                                    hits.var_v[sonar])  # fmt: skip
                except MemoryError:
                    raise out_of_memory(self.resolution) from None
                return
        self._scatter_written(samples)

    def _scatter_written(self, samples: Samples) -> None:
        """:meth:`integrate`'s scatter through the written training samples of
        :func:`~undertow.mapping.tpu.tpu_training` and the generic product-kernel scatter
        (the reference of the scatter from the rays)."""
        hits = tpu_hit_weights(samples, **self._settings())
        points, label, weight, lengths = tpu_training(samples, hits, **self._settings())
        # the product kernel's l_j = s_j (l_max_j - l_min_j) + l_min_j with bounds (0, 1):
        # s_j = l_j / cap gives each sample its own lengths (cap fixed by the settings, so
        # a sample's lengths do not depend on the batch: tiles map as the whole)
        cap = np.full(3, max(self.max_length, self.resolution / 2))
        training = Samples.from_points(points, label, weight, lengths / cap)
        bounds = (np.zeros(3), np.ones(3))
        self._grid_scatter(MODE_PRODUCT, training, bounds, np.zeros(3), cap)
        try:
            self.columns.add_written(*hits)
            hit = samples.label > 0.5
            sonar = (samples.sensor[hit] == SENSOR_SONAR) & (samples.ray[hit] >= 0)
            if self.sonar_carve and sonar.any() and len(samples.origins):
                origin = samples.origins[samples.ray[hit][sonar]]
                offset = samples.points[hit][sonar] - origin
                r = np.linalg.norm(offset, axis=1)
                with np.errstate(invalid="ignore", divide="ignore"):
                    self._carve(origin, offset / r[:, None], r, hits[5][sonar])
        except MemoryError:
            raise out_of_memory(self.resolution) from None

    def _carve(self, origin, direction, r, var_v) -> None:
        """Carve the sonar pings' cones (:mod:`~undertow.mapping.carve`) unless turned off."""
        if self.sonar_carve:
            half = np.deg2rad(self.sonar_beam_width_deg) / 2.0
            self.columns.add_carve(origin, direction, r, var_v, half, self.max_length)

    def seed(self, prior: OccupancyMap | str | Path) -> OccupancyMap:
        """:meth:`Mapper.seed`, and the prior's column sums (a ``tpu`` map's)."""
        prior = super().seed(prior)
        self.columns.add_stats(prior.columns)
        return prior

    def column_stats(self):
        """The column sums (:class:`~undertow.occupancy.ColumnStats`,
        :meth:`~undertow.mapping.columns.ColumnGrid.stats`)."""
        return self.columns.stats()

    def metadata(self) -> dict:
        return {**super().metadata(), "base_length": self.base_length,
                "max_length": self.max_length, "range_std": list(self.range_std),
                "range_std_fraction": self.range_std_fraction,
                "sonar_beam_width_deg": self.sonar_beam_width_deg,
                "sonar_carve": self.sonar_carve,
                "wave": None if self.wave is None else
                {"amplitude_m": self.wave[0], "frequency_hz": self.wave[1]},
                "depth_wave": None if self.depth_wave is None else
                dict(zip(("amplitude_m", "frequency_hz", "depth_std_m", "interval_s"),
                         self.depth_wave, strict=True))}  # fmt: skip


def out_of_memory(resolution: float) -> ConfigError:
    """The one-line error for a map that ran out of memory anyway (after the estimate)."""
    return ConfigError(
        f"mapping ran out of memory at resolution {resolution:g} m: use a coarser resolution "
        "(or a lower mapping.max_memory_gb, checked before mapping)"
    )


def mapper_from_config(config: MappingConfig, prior=None) -> Mapper:
    """The config's mapper with its (checked) values, optionally seeded from a prior map (an
    :class:`~undertow.occupancy.OccupancyMap` or a saved ``map.npz``)."""
    base = {"resolution": config.resolution, "alpha0": config.alpha0, "beta0": config.beta0,
            "max_memory_gb": config.max_memory_gb,
            "resident_mb": config.resident_mb}  # fmt: skip
    if config.method == "csm":
        mapper: Mapper = CsmMapper(**base)
    elif config.method == "bki":
        mapper = BkiMapper(length_scale=config.length_scale, **base)
    elif config.method == "tpu":
        mapper = TpuBkiMapper(base_length=config.base_length, max_length=config.max_length,
                              range_std=(config.range_std_dvl, config.range_std_sonar,
                                         config.range_std_multibeam),
                              sonar_beam_width_deg=config.sonar_beam_width_deg,
                              sonar_carve=config.sonar_carve,
                              wave=config.wave if config.wave_range_noise else None,
                              depth_wave=depth_wave_of(config),
                              range_std_fraction=config.range_std_fraction, **base)  # fmt: skip
    else:
        mapper = AdaptiveBkiMapper(l_min=config.l_min, l_max=config.l_max,
                                   variance_bounds=config.variance_bounds, **base)  # fmt: skip
    if prior is not None:
        mapper.seed(prior)
    return mapper


def make_mapper(method: Method, prior=None, **settings) -> Mapper:
    """A mapper by name ("csm", "bki", "adaptive"), optionally seeded from a prior map.

    ``settings`` are :class:`~undertow.mapping.config.MappingConfig` fields (``resolution``,
    ``length_scale``, ``l_min``, ``l_max``, ``alpha0``, ``beta0``, ``variance_bounds``,
    ``max_memory_gb``); the ones not given take its defaults, and all are checked there."""
    return mapper_from_config(MappingConfig.from_dict({"method": method, **settings}), prior)
