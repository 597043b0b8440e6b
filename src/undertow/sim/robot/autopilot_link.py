"""The virtual autopilot on the virtual robot's MAVLink link: a thread that reads what arrives
on the :class:`~undertow.sim.robot.mavlink.MavlinkSender`'s connection (the replies of a
receiver to ``udpout``, or the client of a ``tcpin:HOST:PORT`` link, which it accepts), hands
each message to a :class:`~undertow.sim.robot.autopilot.VirtualAutopilot` and sends the
replies and the due messages back on the same link and sequence.

The autopilot's clock is the playback clock: t = tau - t0 (s since the log's start, the
autopilot's boot), so ``undertow serve --rate R`` runs it R times faster, like the sensors
(and like the SITL's ``--speedup``). The attitude it rotates body odometry with is the one the
sender reports (ATTITUDE), and its baro depth the log's pressure, d = (p - p0) / (1000 g)
(ArduSub's water depth with specific gravity 1, relative to the pressure at boot p0).
"""

from __future__ import annotations

import threading

import numpy as np

from ...log import G0
from .autopilot import VirtualAutopilot
from .mavlink import MavlinkSender


def log_attitude(sender: MavlinkSender):
    """attitude(t): the roll, pitch, yaw (rad) of the newest IMU row at autopilot time t, or
    None when the log has none."""
    imu = sender.log.imu
    if sender.rpy is None or imu is None or not len(imu):
        return None

    def attitude(t: float) -> tuple[float, float, float]:
        clock = sender.clock
        row, _, _ = clock.latest(imu.t, clock.t0 + t)
        return tuple(float(v) for v in sender.rpy[max(row, 0)])

    return attitude


def log_depth(sender: MavlinkSender):
    """depth(t): the baro depth (m) of the newest pressure row at autopilot time t (module
    docstring), or None when the log has no pressure."""
    p = sender.log.pressure
    if p is None or not len(p):
        return None
    p0 = float(np.nanmedian(p.pressure[: min(len(p), 10)]))

    def depth(t: float) -> float:
        clock = sender.clock
        row, _, _ = clock.latest(p.t, clock.t0 + t)
        return (float(p.pressure[max(row, 0)]) - p0) / (1000.0 * G0)

    return depth


class AutopilotLink:
    """Runs ``autopilot`` on ``sender``'s connection in a thread (module docstring)."""

    def __init__(self, autopilot: VirtualAutopilot, sender: MavlinkSender) -> None:
        self.autopilot = autopilot
        self.sender = sender
        self.error: BaseException | None = None
        self.received = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def now(self) -> float:
        clock = self.sender.clock
        return 0.0 if clock is None else clock.now() - clock.t0

    def start(self) -> AutopilotLink:
        self._thread = threading.Thread(target=self._main, name="serve-autopilot", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _send(self, messages, now: float) -> None:
        clock = self.sender.clock
        at = now + (clock.t0 if clock is not None else 0.0)
        for msg in messages:
            self.sender.send(msg, at)

    def _main(self) -> None:
        ap = self.autopilot
        try:
            while not self._stop.is_set():
                conn = self.sender.conn
                msg = conn.recv_match(blocking=True, timeout=0.01) if conn is not None else None
                now = self.now()
                if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) != (
                    ap.system,
                    ap.component,
                ):
                    self.received += 1
                    self._send(ap.handle(msg, now), now)
                self._send(ap.poll(now), now)
                if conn is None:
                    self._stop.wait(0.01)
        except BaseException as exc:  # reported by the session, never silent
            self.error = exc
