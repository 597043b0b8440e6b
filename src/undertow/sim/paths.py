"""Plan-view paths of the free vehicle from way points: straight legs between the points, each
corner rounded by a circular arc of radius r, tangent to both legs.

For a turn phi at point P_i (left positive, between the unit directions u_in and u_out of its
legs) the arc starts T_i = r tan(|phi| / 2) before P_i on the incoming leg and ends T_i after it
on the outgoing one; the heading psi is constant on a leg and changes linearly in arc length on
an arc (yaw rate V / r at speed V). :func:`corner_geometry` gives the corners (the scenario
checks use it to refuse legs too short for their two arcs), :func:`waypoint_path` samples the
whole path (:class:`~undertow.sim.motion.WaypointMotion` follows it).
"""

from __future__ import annotations

import numpy as np


def corner_geometry(points: np.ndarray, radius: float):
    """Per interior point i: unit directions in/out, turn phi_i (rad, left positive) and the
    tangent length T_i = r tan(|phi_i| / 2) (arc from P_i - T_i u_in to P_i + T_i u_out)."""
    d = np.diff(points, axis=0)
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    cross = u[:-1, 0] * u[1:, 1] - u[:-1, 1] * u[1:, 0]
    dot = np.sum(u[:-1] * u[1:], axis=1)
    phi = np.arctan2(cross, dot)
    return u, length, phi, radius * np.tan(np.abs(phi) / 2)


def waypoint_path(points: np.ndarray, radius: float, ds: float = 0.01):
    """(s, xy, psi) sampled every ~``ds`` m along the polyline with arcs of ``radius`` at the
    corners; psi is exact (constant on a leg, linear in s on an arc), unwrapped."""
    u, length, phi, tang = corner_geometry(points, radius)
    heading = np.arctan2(u[:, 1], u[:, 0])
    cut = np.concatenate([[0.0], tang]), np.concatenate([tang, [0.0]])
    xy, psi = [points[:1]], [heading[:1]]
    for i in range(len(u)):
        a = points[i] + cut[0][i] * u[i]
        b = points[i + 1] - cut[1][i] * u[i]
        n = max(int(np.ceil(np.linalg.norm(b - a) / ds)), 1)
        w = np.linspace(0.0, 1.0, n + 1)[1:]
        xy.append(a + w[:, None] * (b - a))
        psi.append(np.full(n, heading[i]))
        if i + 1 < len(u) and phi[i] != 0.0:
            side = np.sign(phi[i])
            centre = b + side * radius * np.array([-u[i, 1], u[i, 0]])
            m = max(int(np.ceil(radius * abs(phi[i]) / ds)), 2)
            ang = heading[i] + np.linspace(0.0, phi[i], m + 1)[1:]
            xy.append(centre + side * radius * np.stack([np.sin(ang), -np.cos(ang)], 1))
            psi.append(ang)
    xy, psi = np.concatenate(xy), np.unwrap(np.concatenate(psi))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return s, xy, psi
