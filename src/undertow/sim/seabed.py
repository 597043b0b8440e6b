"""Seabeds as heightfields: the floor depth z_floor(x, y) (m, positive down) on a regular grid.

One :class:`Heightfield` is THE floor: the ray caster (DVL beams, the sonar cone, tank.py), the
ground-truth cloud and the scenario checks all read it through the same bilinear interpolation

    z(x, y) = (1-t_x)(1-t_y) z_ij + t_x (1-t_y) z_i+1,j + (1-t_x) t_y z_i,j+1 + t_x t_y z_i+1,j+1,
    i = floor((x - x_0) / dx), t_x = (x - x_0) / dx - i  (likewise j, t_y),

clamped at the grid's edges (outside it the edge values continue). Within a cell the gradient of
the interpolant is a convex combination of the cell's edge differences, so
|grad z| <= G = sqrt(G_x^2 + G_y^2) with G_x = max |z_i+1,j - z_ij| / dx (likewise G_y): the
Lipschitz bound the ray marcher uses to take safe steps (tank.py).

Forms (``floor.kind`` in the scenario):

- ``procedural`` (:func:`procedural_heightfield`), the sum, in depth, of
  - a plane of gradient angle alpha deepening toward the direction psi_s, through the still-water
    depth h at a reference point: z = h + tan(alpha) ((x - x_r) cos psi_s + (y - y_r) sin psi_s);
    sediment beds lie well below sand's angle of repose, ~32 deg (Soulsby 1997, "Dynamics of
    Marine Sands", Thomas Telford, sec. 2.3): coastal and shelf slopes are 0.1-5 deg;
  - sand ripples, a sinusoid of wavelength lambda_r and crest-to-trough height eta_r whose crest
    lines run along the direction theta_c: z -= (eta_r / 2) cos(2 pi n / lambda_r + phi_r),
    n = -(x sin theta_c) + y cos theta_c the distance across the crests; wave ripples have
    lambda_r ~ 0.1-1 m, eta_r ~ 0.01-0.15 m and steepness eta_r / lambda_r <= ~0.2 (Soulsby 1997,
    sec. 7.2; Nielsen 1992, "Coastal Bottom Boundary Layers and Sediment Transport", ch. 3);
  - roughness, a seeded stationary Gaussian random field with the isotropic power-law 2-D
    spectrum W(K) = w K^-gamma (K the horizontal wavenumber, rad/m) between K_min = 2 pi /
    lambda_max and K_max = 2 pi / lambda_min, its strength w set by the RMS height sigma:
    sigma^2 = integral W d^2K = 2 pi w integral_{K_min}^{K_max} K^(1-gamma) dK. Measured sandy
    and gravelly seafloors have gamma ~ 2.5-3.5 and sigma ~ 0.005-0.05 m over decimetre to metre
    scales (Jackson & Richardson 2007, "High-Frequency Seafloor Acoustics", Springer, ch. 5 and
    tables of measured roughness spectra);
  - rocks resting on that floor: boxes with rounded top edges (the tank's rock platform, tank.py)
    and ellipsoidal boulders (the upper half of an ellipsoid, r = c sqrt(1 - (x'/a)^2 -
    (y'/b)^2)), each at the floor depth z_c under its centre: z = min(z, z_c - r) over its
    footprint; boulders are clasts over 0.256 m (Wentworth 1922, J. Geology 30, 377-392);
- ``file`` (:func:`file_heightfield`): a GeoTIFF raster (rasterio) or an XYZ / PLY point set
  (gridded by linear interpolation on its Delaunay triangulation, the nearest point outside the
  hull), placed in the scenario frame by a rotation theta about z and an offset:
  (x, y) = R(theta) (x_f, y_f) + (o_x, o_y); z = o_z - v for elevations v (positive up, e.g.
  GEBCO or a DEM) or z = o_z + v for depths.

The tank's sloped beach (wave-absorbing, at x = 0, the end the waves run to) sets
z = min(z, h x / l_b) for x < l_b: plane beaches in wave basins slope ~1:4-1:10 (Hughes 1993,
"Physical Models and Laboratory Techniques in Coastal Engineering", World Scientific, ch. 6).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numba import njit

from ..errors import ConfigError


@dataclass(frozen=True, eq=False)
class Heightfield:
    """Floor depth ``z`` (nx, ny) (m, positive down) at the nodes x_0 + i dx, y_0 + j dy."""

    x0: float
    y0: float
    dx: float
    dy: float
    z: np.ndarray

    @property
    def grid(self) -> np.ndarray:
        """(x_0, y_0, dx, dy) as the kernels take it."""
        return np.array([self.x0, self.y0, self.dx, self.dy], dtype=np.float64)

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node coordinates (xs (nx,), ys (ny,))."""
        nx, ny = self.z.shape
        return self.x0 + self.dx * np.arange(nx), self.y0 + self.dy * np.arange(ny)

    def sample(self, x, y) -> np.ndarray:
        """Bilinear z(x, y) (the module docstring), any broadcastable shapes."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        out = _sample_many(x.ravel(), y.ravel(), self.z, self.grid)
        return out.reshape(x.shape)

    @cached_property
    def lipschitz(self) -> float:
        """G = sqrt(G_x^2 + G_y^2), a bound on |grad z| of the interpolant (computed once)."""
        gx = float(np.abs(np.diff(self.z, axis=0)).max(initial=0.0)) / self.dx
        gy = float(np.abs(np.diff(self.z, axis=1)).max(initial=0.0)) / self.dy
        return float(np.hypot(gx, gy))


@njit(cache=True)
def bilinear(x, y, z, g):
    """z(x, y) of the grid ``z`` with g = (x_0, y_0, dx, dy), clamped at the edges."""
    nx, ny = z.shape
    fx = min(max((x - g[0]) / g[2], 0.0), nx - 1.0)
    fy = min(max((y - g[1]) / g[3], 0.0), ny - 1.0)
    i = min(int(fx), nx - 2)
    j = min(int(fy), ny - 2)
    tx = fx - i
    ty = fy - j
    return (1.0 - ty) * ((1.0 - tx) * z[i, j] + tx * z[i + 1, j]) + ty * (
        (1.0 - tx) * z[i, j + 1] + tx * z[i + 1, j + 1]
    )


@njit(cache=True)
def _sample_many(x, y, z, g):
    out = np.empty(x.size)
    for k in range(x.size):
        out[k] = bilinear(x[k], y[k], z, g)
    return out


def grid_over(x_min: float, x_max: float, y_min: float, y_max: float, resolution: float):
    """Nodes spanning [x_min, x_max] x [y_min, y_max] exactly, spacing <= ``resolution``:
    (x0, y0, dx, dy, nx, ny)."""
    nx = max(int(np.ceil((x_max - x_min) / resolution - 1e-9)), 1) + 1
    ny = max(int(np.ceil((y_max - y_min) / resolution - 1e-9)), 1) + 1
    return x_min, y_min, (x_max - x_min) / (nx - 1), (y_max - y_min) / (ny - 1), nx, ny


# --- procedural components (depth contributions on node arrays X, Y, indexing "ij") ---------


def plane_depth(X, Y, depth, gradient_deg, downslope_deg, x_ref, y_ref):
    """z = h + tan(alpha) ((x - x_r) cos psi_s + (y - y_r) sin psi_s)."""
    psi = np.deg2rad(downslope_deg)
    along = (X - x_ref) * np.cos(psi) + (Y - y_ref) * np.sin(psi)
    return depth + np.tan(np.deg2rad(gradient_deg)) * along


def ripple_elevation(X, Y, wavelength, height, crest_deg, phase_deg=0.0):
    """eta = (eta_r / 2) cos(2 pi n / lambda_r + phi_r), n across the crests (positive UP)."""
    c = np.deg2rad(crest_deg)
    n = -X * np.sin(c) + Y * np.cos(c)
    return 0.5 * height * np.cos(2 * np.pi * n / wavelength + np.deg2rad(phase_deg))


def _wavenumber_grid(nx: int, ny: int, dx: float, dy: float):
    kx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    ky = 2 * np.pi * np.fft.rfftfreq(ny, dy)
    return np.hypot(kx[:, None], ky[None, :])


def random_field(nx, ny, dx, dy, rms, gamma, min_wavelength, max_wavelength, rng) -> np.ndarray:
    """Gaussian random field (nx, ny) with E[sigma^2] = rms^2 and spectrum W(K) ~ K^-gamma on
    K_min <= K <= K_max (the module docstring): white noise n, f = F^-1[F[n] sqrt(W) / c] with
    c^2 = (1/N) sum_K W(K) / rms^2 over the full N = nx ny frequency grid, so that
    E[var f] = (1/N) sum_K W(K) / c^2 = rms^2. The grid is periodic (a torus)."""
    if rms <= 0:
        return np.zeros((nx, ny))
    K = _wavenumber_grid(nx, ny, dx, dy)
    band = (K >= 2 * np.pi / max_wavelength) & (K <= 2 * np.pi / min_wavelength) & (K > 0)
    W = np.zeros_like(K)
    W[band] = K[band] ** (-gamma)
    # rfft keeps ky >= 0: the full-grid sum counts the columns 0 < ky < Nyquist twice
    weight = np.full(K.shape[1], 2.0)
    weight[0] = 1.0
    if ny % 2 == 0:
        weight[-1] = 1.0
    total = float((W * weight[None, :]).sum())
    if total <= 0:
        return np.zeros((nx, ny))
    c = np.sqrt(total / (nx * ny)) / rms
    spectrum = np.fft.rfft2(rng.standard_normal((nx, ny))) * np.sqrt(W) / c
    return np.fft.irfft2(spectrum, s=(nx, ny))


def rounded_box_height(xl, yl, length, width, height, edge_radius):
    """Height r above the floor of a box with rounded top edges, in its own frame (xl, yl):
    r = H inside the rectangle shrunk by rho, H - rho + sqrt(rho^2 - d_e^2) on the fillet
    (d_e <= rho), NaN outside the footprint (tank.py's rock platform)."""
    dx_ = np.maximum(np.abs(xl) - (0.5 * length - edge_radius), 0.0)
    dy_ = np.maximum(np.abs(yl) - (0.5 * width - edge_radius), 0.0)
    d_e = np.hypot(dx_, dy_)
    r = height - edge_radius + np.sqrt(np.maximum(edge_radius**2 - d_e**2, 0.0))
    return np.where(d_e <= edge_radius, r, np.nan)


def boulder_height(xl, yl, length, width, height):
    """r = c sqrt(1 - (x'/a)^2 - (y'/b)^2), a = length / 2, b = width / 2, c = height; NaN
    outside the footprint."""
    q = (2 * xl / length) ** 2 + (2 * yl / width) ** 2
    return np.where(q < 1.0, height * np.sqrt(np.maximum(1.0 - q, 0.0)), np.nan)


def place_rock(z, xs, ys, base: Heightfield, rock) -> None:
    """z = min(z, z_c - r) over the rock's footprint, z_c the ``base`` floor under its centre;
    ``rock`` has kind ('box' | 'boulder'), center_x_m, center_y_m, length_m, width_m, height_m,
    yaw_deg and (box) edge_radius_m. In place, on the rock's bounding box only."""
    half = 0.5 * np.hypot(rock.length_m, rock.width_m)
    i0, i1 = np.searchsorted(xs, [rock.center_x_m - half, rock.center_x_m + half])
    j0, j1 = np.searchsorted(ys, [rock.center_y_m - half, rock.center_y_m + half])
    i0, j0 = max(i0 - 1, 0), max(j0 - 1, 0)
    if i1 <= i0 or j1 <= j0:
        return
    X, Y = np.meshgrid(xs[i0 : i1 + 1] - rock.center_x_m, ys[j0 : j1 + 1] - rock.center_y_m,
                       indexing="ij")  # fmt: skip
    yaw = np.deg2rad(rock.yaw_deg)
    xl = np.cos(yaw) * X + np.sin(yaw) * Y
    yl = -np.sin(yaw) * X + np.cos(yaw) * Y
    if rock.kind == "box":
        r = rounded_box_height(xl, yl, rock.length_m, rock.width_m, rock.height_m,
                               rock.edge_radius_m)  # fmt: skip
    else:
        r = boulder_height(xl, yl, rock.length_m, rock.width_m, rock.height_m)
    z_c = float(base.sample(rock.center_x_m, rock.center_y_m))
    block = z[i0 : i1 + 1, j0 : j1 + 1]
    inside = np.isfinite(r)
    block[inside] = np.minimum(block[inside], z_c - r[inside])


def apply_beach(z, xs, depth: float, length: float) -> None:
    """z = min(z, h x / l_b) for x < l_b (in place): a plane beach from the floor at x = l_b up
    to the still-water line at x = 0."""
    if length <= 0:
        return
    near = xs < length
    z[near] = np.minimum(z[near], depth * xs[near, None] / length)


def procedural_heightfield(floor, depth: float, domain, platform=None, beach_m: float = 0.0):
    """The ``procedural`` floor (module docstring) over ``domain`` = (x_min, x_max, y_min,
    y_max) at ``floor.resolution_m``; ``platform`` (a box rock) is placed like ``floor.rocks``.
    The plane's reference point defaults to the domain's centre."""
    x0, y0, dx, dy, nx, ny = grid_over(*domain, floor.resolution_m)
    xs, ys = x0 + dx * np.arange(nx), y0 + dy * np.arange(ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    sl, rp, rg = floor.slope, floor.ripples, floor.roughness
    x_ref = 0.5 * (domain[0] + domain[1]) if sl.reference_x_m is None else sl.reference_x_m
    y_ref = 0.5 * (domain[2] + domain[3]) if sl.reference_y_m is None else sl.reference_y_m
    z = plane_depth(X, Y, depth, sl.gradient_deg, sl.downslope_deg, x_ref, y_ref)
    if rp.height_m > 0:
        z -= ripple_elevation(X, Y, rp.wavelength_m, rp.height_m, rp.crest_deg, rp.phase_deg)
    rng = np.random.default_rng(floor.seed)
    z -= random_field(nx, ny, dx, dy, rg.rms_m, rg.spectral_slope, rg.min_wavelength_m,
                      rg.max_wavelength_m, rng)  # fmt: skip
    del X, Y
    base = Heightfield(x0, y0, dx, dy, z.copy())
    for rock in ([platform] if platform is not None else []) + list(floor.rocks):
        place_rock(z, xs, ys, base, rock)
    apply_beach(z, xs, depth, beach_m)
    return Heightfield(x0, y0, dx, dy, z)


def flat_heightfield(floor, depth: float, domain, platform=None, beach_m: float = 0.0):
    """A flat floor at ``depth`` with the platform and beach, as a heightfield (for a flat tank
    with a beach or without walls)."""
    x0, y0, dx, dy, nx, ny = grid_over(*domain, floor.resolution_m)
    xs, ys = x0 + dx * np.arange(nx), y0 + dy * np.arange(ny)
    z = np.full((nx, ny), float(depth))
    base = Heightfield(x0, y0, dx, dy, z.copy())
    if platform is not None:
        place_rock(z, xs, ys, base, platform)
    apply_beach(z, xs, depth, beach_m)
    return Heightfield(x0, y0, dx, dy, z)


# --- bathymetry files ------------------------------------------------------------------------


def _one_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def read_geotiff(path: Path):
    """(values (rows, cols) with NaN at nodata, affine (a, b, c, d, e, f)) of band 1: pixel
    (col, row) has its centre at x = a (col + 1/2) + b (row + 1/2) + c, y = d (col + 1/2) +
    e (row + 1/2) + f."""
    try:
        import rasterio
    except ImportError:  # pragma: no cover - rasterio is a dependency
        raise ConfigError(
            f"{path}: reading a GeoTIFF floor needs rasterio (pip install rasterio)"
        ) from None
    try:
        with rasterio.open(path) as src:
            values = src.read(1, masked=True).astype(float).filled(np.nan)
            t = src.transform
    except Exception as exc:  # rasterio raises its own error classes for every bad file
        raise ConfigError(f"{path}: not a readable GeoTIFF: {_one_line(exc)}") from None
    if values.size < 4 or min(values.shape) < 2 or not np.isfinite(values).any():
        raise ConfigError(f"{path}: a GeoTIFF floor needs at least 2 x 2 valid pixels")
    return values, (t.a, t.b, t.c, t.d, t.e, t.f)


def read_points(path: Path) -> np.ndarray:
    """(M, 3) points of an XYZ text file (x y z per line, spaces or commas, '#' comments) or a
    PLY file; ConfigError naming the file if it is not one."""
    if path.suffix.lower() == ".ply":
        from ..errors import ReaderError
        from ..io.ply import read_ply

        try:
            pts = np.asarray(read_ply(path)[0], float)
        except ReaderError as exc:
            raise ConfigError(f"{path}: not a readable PLY floor: {_one_line(exc)}") from None
    else:
        try:
            text = path.read_text(encoding="utf-8").replace(",", " ")
            rows = [ln.split("#")[0].split() for ln in text.splitlines()]
            pts = np.array([[float(v) for v in r[:3]] for r in rows if r], float)
        except (OSError, UnicodeDecodeError, ValueError, IndexError) as exc:
            raise ConfigError(
                f"{path}: not an XYZ floor (x y z per line): {_one_line(exc)}"
            ) from None
    if pts.ndim != 2 or pts.shape[0] < 3 or pts.shape[1] < 3 or not np.isfinite(pts).all():
        raise ConfigError(f"{path}: an XYZ / PLY floor needs >= 3 finite x y z points")
    return pts[:, :3]


def _to_file_frame(X, Y, offset, rotation_deg):
    """(x_f, y_f) = R(-theta) ((x, y) - (o_x, o_y))."""
    th = np.deg2rad(rotation_deg)
    dx_, dy_ = X - offset[0], Y - offset[1]
    return np.cos(th) * dx_ + np.sin(th) * dy_, -np.sin(th) * dx_ + np.cos(th) * dy_


def _sample_raster(values, affine, xf, yf):
    """Bilinear raster values at file coordinates (clamped at the edges, nodata filled with the
    nearest valid pixel)."""
    from scipy import ndimage

    bad = ~np.isfinite(values)
    if bad.any():
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        values = values[tuple(idx)]
    a, b, c, d, e, f = affine
    det = a * e - b * d
    col = (e * (xf - c) - b * (yf - f)) / det - 0.5
    row = (-d * (xf - c) + a * (yf - f)) / det - 0.5
    return ndimage.map_coordinates(values, [row.ravel(), col.ravel()], order=1,
                                   mode="nearest").reshape(xf.shape)  # fmt: skip


def _sample_points(pts, xf, yf):
    """Linear interpolation on the points' Delaunay triangulation, the nearest point outside."""
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
    from scipy.spatial import QhullError

    try:
        lin = LinearNDInterpolator(pts[:, :2], pts[:, 2])
    except (QhullError, ValueError) as exc:
        raise ConfigError(
            f"points cannot be triangulated (all on a line?): {_one_line(exc)}"
        ) from None
    out = lin(xf, yf)
    miss = ~np.isfinite(out)
    if miss.any():
        out[miss] = NearestNDInterpolator(pts[:, :2], pts[:, 2])(xf[miss], yf[miss])
    return out


def file_heightfield(floor, domain, platform=None, depth: float = 0.0, beach_m: float = 0.0):
    """The ``file`` floor (module docstring) gridded over ``domain`` at ``floor.resolution_m``."""
    path = Path(floor.file)
    if not path.is_file():
        raise ConfigError(f"{path}: no such bathymetry file")
    x0, y0, dx, dy, nx, ny = grid_over(*domain, floor.resolution_m)
    xs, ys = x0 + dx * np.arange(nx), y0 + dy * np.arange(ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    xf, yf = _to_file_frame(X, Y, floor.offset_m, floor.rotation_deg)
    if path.suffix.lower() in (".tif", ".tiff", ".gtiff"):
        values, affine = read_geotiff(path)
        v = _sample_raster(values, affine, xf, yf)
    else:
        try:
            v = _sample_points(read_points(path), xf, yf)
        except ConfigError as exc:
            message = str(exc)
            raise ConfigError(
                message if message.startswith(str(path)) else f"{path}: {message}"
            ) from None
    z = floor.offset_m[2] - v if floor.values == "elevation" else floor.offset_m[2] + v
    base = Heightfield(x0, y0, dx, dy, z.copy())
    for rock in ([platform] if platform is not None else []) + list(floor.rocks):
        place_rock(z, xs, ys, base, rock)
    apply_beach(z, xs, depth, beach_m)
    return Heightfield(x0, y0, dx, dy, z)


# --- the scenario's floor ------------------------------------------------------------------


def uses_heightfield(s) -> bool:
    """False for the original tank (flat floor, rock platform, four walls, no beach), which
    tank.py's closed-form kernel casts against exactly; True otherwise."""
    return s.floor.kind != "flat" or s.tank.beach.length_m > 0 or not s.tank.walls


def scenario_heightfield(s) -> Heightfield | None:
    """The scenario's floor as a :class:`Heightfield` over the tank (``[0, L] x [-W/2, W/2]``),
    None for the original flat tank; cached on the floor-defining fields (a file also on its
    modification time), so checking and simulating a scenario build it once."""
    if not uses_heightfield(s):
        return None
    key = {"floor": s.floor.model_dump(mode="json"), "tank": s.tank.model_dump(mode="json"),
           "depth": s.water.depth_m}  # fmt: skip
    if s.floor.file is not None:
        try:
            key["mtime"] = Path(s.floor.file).stat().st_mtime_ns
        except OSError:
            key["mtime"] = None
    key_text = json.dumps(key, sort_keys=True)
    if key_text not in _CACHE:
        if len(_CACHE) >= 2:  # two floors at most (~50 MB each for a large field)
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key_text] = _build(s.floor, s.tank, s.water.depth_m)
    return _CACHE[key_text]


_CACHE: dict[str, Heightfield] = {}


def _build(floor, tank, depth: float) -> Heightfield:
    domain = (0.0, tank.length_m, -0.5 * tank.width_m, 0.5 * tank.width_m)
    platform = _platform(tank.rock)
    beach = tank.beach.length_m
    if floor.kind == "procedural":
        return procedural_heightfield(floor, depth, domain, platform, beach)
    if floor.kind == "file":
        return file_heightfield(floor, domain, platform, depth, beach)
    return flat_heightfield(floor, depth, domain, platform, beach)


@dataclass(frozen=True)
class _Box:
    center_x_m: float
    center_y_m: float
    length_m: float
    width_m: float
    height_m: float
    edge_radius_m: float
    yaw_deg: float = 0.0
    kind: str = "box"


def _platform(rock) -> _Box:
    """The tank's rock platform (scenario ``tank.rock``) as a box rock."""
    return _Box(rock.center_x_m, rock.center_y_m, rock.length_m, rock.width_m, rock.height_m,
                rock.edge_radius_m)  # fmt: skip
