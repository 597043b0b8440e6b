"""Robot motion: the towing carriage (rigid mount) and the free vehicle (rock survey).

Both give the body pose p(t) (world, z down) and roll-pitch-yaw at any times; velocities,
accelerations and body rates follow by central differences of that pose (``kinematics``):

    v = (p(t+h) - p(t-h)) / 2h,   a = (p(t+h) - 2 p(t) + p(t-h)) / h^2,
    [omega_b]_x = R^T (R(t+h) - R(t-h)) / 2h     (antisymmetric part, body rates p q r).

Carriage: trapezoidal speed profile s(t) (rest, accelerate at A to V, cruise, decelerate, rest)
along +x over the run length L (triangular if L < V^2/A). The rigid strut is shaken by the wave
part of the Morison force along the wave heading e_beta, quasi-statically (strut natural
frequency far above f):

    delta(t) = F(t) / K,   F = rho C_M V_b du_w/dt + 1/2 rho C_D A_f (|u_r| u_r + |u_c| u_c),
    u_r = u_w - u_c,  u_c = carriage velocity along e_beta, u_w the orbital velocity there.

The drag term is the Morison drag on the relative velocity, 1/2 rho C_D A_f |u_r| u_r, minus its
calm-water value 1/2 rho C_D A_f |-u_c| (-u_c) (the steady towing drag, which the strut carries
from the start of the run and which is no wave load): hence ``+ |u_c| u_c``. F = 0 in calm water;
at rest (u_c = 0) F = rho C_M V_b U omega sin(theta) + 1/2 rho C_D A_f U^2 |cos theta| cos theta
(inertia linear, drag quadratic in the amplitude); at cruise with |u_w| < |u_c| the drag term is
1/2 rho C_D A_f (2 |u_c| u_w - sign(u_c) u_w^2), nearly linear, at the encounter frequency
omega + k V (oncoming waves).

Free vehicle: a plan-view path (x_p(s), y_p(s), psi(s)) by arc length s -- lawnmower passes
(straight legs along x joined by half circles) or way points joined by straight legs whose
corners are circular arcs of radius r (tangent length r tan(|phi|/2) for a turn phi; yaw rate
V / r on the arc; :mod:`undertow.sim.paths`) -- followed at speed V with ramps at a commanded
depth d, plus the orbital particle displacement xi(x, d, t) at the vehicle (it is carried by the
flow); roll and pitch follow the local slope of the orbital surface through the vehicle, scaled
by an attitude gain G:

    p(t) = (x_p, y_p, d) + xi(x_p, y_p, d, t),   yaw = psi,
    pitch = G sigma cos(beta - psi),   roll = -G sigma sin(beta - psi),
    sigma = d zeta_up / d s_beta = -k (W / omega) sin(theta).

On a straight leg at speed V and heading psi the wave phase at the vehicle advances at
d theta / dt = k V cos(beta - psi) - omega: the vehicle heaves at the encounter frequency
omega_e = |omega - k V cos(beta - psi)| (Faltinsen, "Sea Loads on Ships and Offshore
Structures", 1990, ch. 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..rotations import rpy_to_matrix
from .paths import waypoint_path
from .scenario.model import CarriageModel, SurveyModel, WaypointsModel
from .wavefield import WaveField
from .waves import LinearWave


def trapezoid_distance(t, length: float, speed: float, accel: float, t0: float) -> np.ndarray:
    """Distance s(t) of a rest-accelerate-cruise-decelerate-rest profile starting at t0
    (0 for a zero length: station keeping)."""
    if length <= 0:
        return np.zeros(np.shape(t))
    v = min(speed, np.sqrt(length * accel))
    ta = v / accel
    tc = (length - v * ta) / v
    tau = np.clip(np.asarray(t, float) - t0, 0.0, 2 * ta + tc)
    s_acc = 0.5 * accel * np.minimum(tau, ta) ** 2
    s_cru = v * np.clip(tau - ta, 0.0, tc)
    td = np.clip(tau - ta - tc, 0.0, ta)
    s_dec = v * td - 0.5 * accel * td**2
    return s_acc + s_cru + s_dec


def trapezoid_duration(length: float, speed: float, accel: float) -> float:
    if length <= 0:
        return 0.0
    v = min(speed, np.sqrt(length * accel))
    return 2 * v / accel + (length - v * v / accel) / v


@dataclass(frozen=True)
class CarriageMotion:
    """Robot rigidly on the towing carriage, heading +x."""

    config: CarriageModel
    wave: LinearWave | WaveField

    @property
    def duration(self) -> float:
        c = self.config
        run = trapezoid_duration(c.run_length_m, c.cruise_speed_m_s, c.acceleration_m_s2)
        return c.hold_before_s + run + c.hold_after_s

    def carriage_position(self, t) -> np.ndarray:
        c = self.config
        t = np.asarray(t, float)
        s = trapezoid_distance(
            t, c.run_length_m, c.cruise_speed_m_s, c.acceleration_m_s2, c.hold_before_s
        )
        return np.stack([c.start_x_m + s, np.full_like(t, c.y_m), np.full_like(t, c.depth_m)], -1)

    def mount_deflection(self, t) -> np.ndarray:
        """delta(t) e_beta (N, 3): the quasi-static Morison deflection of the strut."""
        c, m, w = self.config, self.config.mount, self.wave
        t = np.asarray(t, float)
        if w.is_calm:
            return np.zeros((t.size, 3))
        p = self.carriage_position(t)
        h = 1e-3
        v_c = (self.carriage_position(t + h) - self.carriage_position(t - h)) / (2 * h)
        e = np.array([np.cos(w.beta), np.sin(w.beta), 0.0])
        u_w = w.orbital_velocity(p[:, 0], p[:, 1], c.depth_m, t) @ e
        du_w = w.orbital_acceleration(p[:, 0], p[:, 1], c.depth_m, t) @ e
        u_c = v_c @ e
        u_r = u_w - u_c
        rho = w.rho
        force = rho * m.inertia_coefficient * m.displaced_volume_m3 * du_w + 0.5 * rho * (
            m.drag_coefficient * m.frontal_area_m2 * (np.abs(u_r) * u_r + np.abs(u_c) * u_c)
        )
        return (force / m.stiffness_n_m)[:, None] * e

    def pose(self, t) -> tuple[np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, float))
        return self.carriage_position(t) + self.mount_deflection(t), np.zeros((t.size, 3))


def free_pose(config, wave, path, t) -> tuple[np.ndarray, np.ndarray]:
    """Pose of a free vehicle following ``path`` = (s, xy, psi) (module docstring): trapezoidal
    speed (ramps ``ramp_s``) after ``hold_before_s``, carried by the orbital flow."""
    c, w = config, wave
    t = np.atleast_1d(np.asarray(t, float))
    s_path, xy, heading = path
    accel = c.speed_m_s / c.ramp_s if c.ramp_s > 0 else 1e6
    s = trapezoid_distance(t, s_path[-1], c.speed_m_s, accel, c.hold_before_s)
    x, y = np.interp(s, s_path, xy[:, 0]), np.interp(s, s_path, xy[:, 1])
    yaw = np.interp(s, s_path, heading)
    disp = w.particle_displacement(x, y, c.depth_m, t)
    pos = np.stack([x, y, np.full_like(x, c.depth_m)], 1) + disp
    rpy = np.zeros((t.size, 3))
    rpy[:, 2] = yaw
    if not w.is_calm:
        slope = w.orbital_slope(x, y, c.depth_m, t)  # d zeta_up / d along
        along_body = np.cos(w.beta - yaw)
        rpy[:, 1] = c.attitude_gain * slope * along_body
        rpy[:, 0] = -c.attitude_gain * slope * np.sin(w.beta - yaw)
    return pos, rpy


def _free_duration(config, length: float) -> float:
    c = config
    accel = c.speed_m_s / c.ramp_s if c.ramp_s > 0 else 1e6
    return c.hold_before_s + trapezoid_duration(length, c.speed_m_s, accel) + c.hold_after_s


@dataclass(frozen=True)
class SurveyMotion:
    """Free vehicle flying lawnmower passes over the rock, carried by the orbital flow."""

    config: SurveyModel
    wave: LinearWave | WaveField

    def _path(self):
        c = self.config
        r = 0.5 * c.pass_spacing_m
        pts = []
        for i in range(c.passes):
            y = c.first_pass_y_m + i * c.pass_spacing_m
            forward = i % 2 == 0
            xs = np.linspace(0.0, c.pass_length_m, max(int(c.pass_length_m / 0.01), 2))
            x = c.start_x_m + (xs if forward else c.pass_length_m - xs)
            pts.append(np.stack([x, np.full_like(x, y)], 1))
            if i + 1 < c.passes:
                ang = np.linspace(-np.pi / 2, np.pi / 2, max(int(np.pi * r / 0.01), 8))[1:-1]
                cx = c.start_x_m + (c.pass_length_m if forward else 0.0)
                sign = 1.0 if forward else -1.0
                pts.append(np.stack([cx + sign * r * np.cos(ang), y + r + r * np.sin(ang)], 1))
        xy = np.concatenate(pts)
        seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        d = np.diff(xy, axis=0)
        heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        return s, xy, np.concatenate([heading, heading[-1:]])

    @property
    def duration(self) -> float:
        s, _, _ = self._path()
        return _free_duration(self.config, s[-1])

    def pose(self, t) -> tuple[np.ndarray, np.ndarray]:
        return free_pose(self.config, self.wave, self._path(), t)


@dataclass(frozen=True)
class WaypointMotion:
    """Free vehicle on straight legs between way points, corners rounded (``waypoint_path``)."""

    config: WaypointsModel
    wave: LinearWave | WaveField

    @cached_property
    def path(self):
        c = self.config
        pts = np.asarray(c.points, float)
        pts = np.concatenate([pts] + [pts[1:]] * (c.laps - 1))
        return waypoint_path(pts, c.turn_radius_m)

    @property
    def duration(self) -> float:
        return _free_duration(self.config, self.path[0][-1])

    def pose(self, t) -> tuple[np.ndarray, np.ndarray]:
        return free_pose(self.config, self.wave, self.path, t)


@dataclass(frozen=True)
class PointKinematics:
    """Kinematics of a point fixed on the body (a sensor): world position, velocity,
    acceleration; the body's rotation R (world from body), rpy and body rates omega_b."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    R: np.ndarray
    rpy: np.ndarray
    omega_body: np.ndarray


def kinematics(motion, t, lever_arm=(0.0, 0.0, 0.0), h: float = 1e-3) -> PointKinematics:
    """Central-difference kinematics of the body point at ``lever_arm`` (m, body frame)."""
    t = np.atleast_1d(np.asarray(t, float))
    r = np.asarray(lever_arm, float)
    ts = np.concatenate([t - h, t, t + h])
    p, rpy = motion.pose(ts)
    R = rpy_to_matrix(rpy)
    q = p + R @ r
    n = t.size
    qm, q0, qp = q[:n], q[n : 2 * n], q[2 * n :]
    Rm, R0, Rp = R[:n], R[n : 2 * n], R[2 * n :]
    Om = np.swapaxes(R0, -1, -2) @ (Rp - Rm) / (2 * h)
    omega = 0.5 * np.stack(
        [Om[:, 2, 1] - Om[:, 1, 2], Om[:, 0, 2] - Om[:, 2, 0], Om[:, 1, 0] - Om[:, 0, 1]], -1
    )
    return PointKinematics(
        t=t,
        position=q0,
        velocity=(qp - qm) / (2 * h),
        acceleration=(qp - 2 * q0 + qm) / (h * h),
        R=R0,
        rpy=rpy[n : 2 * n],
        omega_body=omega,
    )
