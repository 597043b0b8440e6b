"""The wave basin: its floor, walls and ray casting onto them.

Two floors. The original tank (``heightfield`` None): a flat floor at depth h with a rock
platform, cast against in closed form as below. Any other floor (procedural, from a file, a
beach, no walls): a :class:`~undertow.sim.seabed.Heightfield` sampled bilinearly, the same
function for rays, the ground-truth cloud and the checks (seabed.py).

World frame z DOWN, origin at the still surface (log.py). The tank spans 0 <= x <= L and
-W/2 <= y <= W/2; the floor is the heightfield

    z_floor(x, y) = h - r(x, y)

where r is the rock platform: a box of length l_r (x), width w_r (y) and height H_r centred at
(x_r, y_r) whose top edges are rounded with radius rho_e (a quarter circle in the vertical plane):
with d_e the plan-view distance from (x, y) to the rectangle shrunk by rho_e,

    r = H_r                                     for d_e <= 0
    r = H_r - rho_e + sqrt(rho_e^2 - d_e^2)     for 0 < d_e <= rho_e   (rounded edge)
    r = 0                                       outside (vertical rock wall below the fillet).

A ray o + s u (|u| = 1) hits the first s where the point is solid: below the floor
(z >= z_floor) or outside the walls. The kernel marches in steps of ``step`` and bisects the
bracket to ``tol``; a ray that reaches the surface (z < 0) or ``max_range`` returns NaN.

Heightfield floors: solid is z >= z_floor(x, y) (bilinear) or, with walls, outside the tank box.
The march steps ds = max(step, g / (G |u_h| + max(u_z, 0))) from a free point whose gap to the
floor is g = z_floor - z: along the ray the gap falls at most at the rate G |u_h| + max(u_z, 0)
(G >= |grad z_floor|, Heightfield.lipschitz), so no floor lies within the step (sphere tracing,
Hart 1996, "Sphere tracing", The Visual Computer 12, 527-545); the walls bound a convex box, so
a step past one still ends in solid. The step stops at the surface crossing s = -o_z / u_z: a
ray free there returns NaN. The bracket is bisected to ``tol`` as above.

The ground-truth cloud (``floor_cloud``) holds the floor on a regular grid and, for the walls the
box reaches (heightfield tanks with walls), the wetted wall strips from the surface down to the
floor at the same spacing: the part of the walls a scan of the empty tank sees under water.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .seabed import Heightfield, bilinear


@dataclass(frozen=True)
class Tank:
    """Basin geometry (m): length, width, water depth h, rock centre/size/edge radius."""

    length: float
    width: float
    depth: float
    rock_x: float
    rock_y: float
    rock_length: float
    rock_width: float
    rock_height: float
    rock_edge_radius: float = 0.0
    walls: bool = True
    heightfield: Heightfield | None = None

    def _params(self) -> np.ndarray:
        return np.array(
            [
                self.length, self.width, self.depth, self.rock_x, self.rock_y,
                self.rock_length, self.rock_width, self.rock_height, self.rock_edge_radius,
            ],
            dtype=np.float64,
        )  # fmt: skip

    def floor_depth(self, x, y) -> np.ndarray:
        """z_floor(x, y) (m, positive down) including the rock; walls not included."""
        if self.heightfield is not None:
            return self.heightfield.sample(x, y)
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        out = _floor_depth_grid(x.ravel(), y.ravel(), self._params())
        return out.reshape(x.shape)

    def cast_rays(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        max_range: float = 50.0,
        step: float = 0.01,
        tol: float = 1e-6,
    ) -> np.ndarray:
        """Range s (m) to the first solid point along each ray (N,), NaN where nothing is hit.

        ``origins`` (N, 3) and ``directions`` (N, 3) in the world frame; directions need not be
        normalized (they are).
        """
        o = np.ascontiguousarray(np.asarray(origins, float).reshape(-1, 3))
        u = np.asarray(directions, float).reshape(-1, 3)
        u = np.ascontiguousarray(u / np.linalg.norm(u, axis=1, keepdims=True))
        hf = self.heightfield
        if hf is None:
            return _cast_rays(o, u, self._params(), float(max_range), float(step), float(tol))
        box = np.array([self.length, self.width, 1.0 if self.walls else 0.0])
        return _cast_rays_grid(o, u, np.ascontiguousarray(hf.z), hf.grid, box, hf.lipschitz,
                               float(max_range), float(step), float(tol))  # fmt: skip

    def floor_cloud(self, x_min, x_max, y_min, y_max, spacing: float) -> np.ndarray:
        """Points (M, 3) on the floor heightfield on a regular grid of ``spacing`` (m),
        clipped to the tank: the simulated equivalent of the paper's dense LiDAR scan."""
        x0, x1 = max(x_min, 0.0), min(x_max, self.length)
        y0, y1 = max(y_min, -self.width / 2), min(y_max, self.width / 2)
        xs = np.arange(x0, x1 + 0.5 * spacing, spacing)
        ys = np.arange(y0, y1 + 0.5 * spacing, spacing)
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        gz = self.floor_depth(gx, gy)
        floor = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
        if self.heightfield is None or not self.walls:
            return floor
        return np.concatenate([floor, self._wall_strips(xs, ys, x0, x1, y0, y1, spacing)])

    def _wall_strips(self, xs, ys, x0, x1, y0, y1, spacing) -> np.ndarray:
        """Points on each wall the box [x0, x1] x [y0, y1] touches, from z = 0 to the floor."""
        L, h = self.length, 0.5 * self.width
        walls = []  # (x of the points, y of the points) along each touched wall
        if y0 <= -h:
            walls.append((xs, np.full(xs.size, -h)))
        if y1 >= h:
            walls.append((xs, np.full(xs.size, h)))
        if x0 <= 0.0:
            walls.append((np.zeros(ys.size), ys))
        if x1 >= L:
            walls.append((np.full(ys.size, L), ys))
        out = [np.empty((0, 3))]
        for wx, wy in walls:  # z = 0, spacing, ... down to the floor under each wall point
            n = np.floor(np.maximum(self.floor_depth(wx, wy), 0.0) / spacing).astype(int) + 1
            idx = np.repeat(np.arange(wx.size), n)
            k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
            out.append(np.column_stack([wx[idx], wy[idx], k * spacing]))
        return np.concatenate(out)


@njit(cache=True)
def _rock_height(x, y, p):
    rho = p[8]
    hx = 0.5 * p[5] - rho
    hy = 0.5 * p[6] - rho
    dx = max(abs(x - p[3]) - hx, 0.0)
    dy = max(abs(y - p[4]) - hy, 0.0)
    d_e = np.sqrt(dx * dx + dy * dy)
    if d_e <= 0.0:
        return p[7]
    if d_e <= rho:
        return p[7] - rho + np.sqrt(rho * rho - d_e * d_e)
    return 0.0


@njit(cache=True)
def _floor_depth_grid(x, y, p):
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = p[2] - _rock_height(x[i], y[i], p)
    return out


@njit(cache=True)
def _solid(x, y, z, p):
    if x < 0.0 or x > p[0] or abs(y) > 0.5 * p[1]:
        return True
    return z >= p[2] - _rock_height(x, y, p)


@njit(cache=True)
def _cast_rays(o, u, p, max_range, step, tol):
    n = o.shape[0]
    out = np.full(n, np.nan)
    for i in range(n):
        s_prev = 0.0
        s = 0.0
        hit = False
        while s < max_range:
            s = min(s_prev + step, max_range)
            z = o[i, 2] + s * u[i, 2]
            if z < 0.0:
                break
            if _solid(o[i, 0] + s * u[i, 0], o[i, 1] + s * u[i, 1], z, p):
                hit = True
                break
            s_prev = s
        if not hit:
            continue
        lo, hi = s_prev, s
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if _solid(o[i, 0] + mid * u[i, 0], o[i, 1] + mid * u[i, 1], o[i, 2] + mid * u[i, 2], p):
                hi = mid
            else:
                lo = mid
        out[i] = hi
    return out


@njit(cache=True)
def _solid_grid(x, y, z, zf, g, box):
    if box[2] > 0.0 and (x < 0.0 or x > box[0] or abs(y) > 0.5 * box[1]):
        return True
    return z >= bilinear(x, y, zf, g)


@njit(cache=True)
def _cast_rays_grid(o, u, zf, g, box, lip, max_range, step, tol):
    n = o.shape[0]
    out = np.full(n, np.nan)
    for i in range(n):
        uh = np.sqrt(u[i, 0] * u[i, 0] + u[i, 1] * u[i, 1])
        rate = lip * uh + max(u[i, 2], 0.0)
        limit = max_range
        if u[i, 2] < 0.0:
            limit = min(limit, -o[i, 2] / u[i, 2])
        gap = bilinear(o[i, 0], o[i, 1], zf, g) - o[i, 2]
        s_prev = 0.0
        s = 0.0
        hit = False
        while s_prev < limit:
            adv = step
            if gap > 0.0:
                adv = max(step, gap / rate) if rate > 0.0 else limit
            s = min(s_prev + adv, limit)
            x = o[i, 0] + s * u[i, 0]
            y = o[i, 1] + s * u[i, 1]
            z = o[i, 2] + s * u[i, 2]
            if _solid_grid(x, y, z, zf, g, box):
                hit = True
                break
            gap = bilinear(x, y, zf, g) - z
            s_prev = s
        if not hit:
            continue
        lo, hi = s_prev, s
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if _solid_grid(o[i, 0] + mid * u[i, 0], o[i, 1] + mid * u[i, 1],
                           o[i, 2] + mid * u[i, 2], zf, g, box):  # fmt: skip
                hi = mid
            else:
                lo = mid
        out[i] = hi
    return out
