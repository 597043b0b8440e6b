"""A virtual Water Linked DVL A50: a TCP server speaking its JSON protocol (json_v3).

Protocol (Water Linked DVL A50 documentation, "JSON protocol over TCP", port 16171): the DVL
writes one JSON object per line to every connected client: ``velocity`` reports (vx, vy, vz m/s,
fom, 3x3 covariance, altitude, four transducers, ``time_of_validity`` and
``time_of_transmission`` in Unix us) and ``position_local`` dead-reckoning reports (``ts`` s,
x y z m, std m, roll pitch yaw in degrees). A client may write commands, one JSON object per line
(``{"command": "get_config"}``, ``reset_dead_reckoning``, ``calibrate_gyro``, ``set_config`` with
``parameters``); each is answered with ``{"type": "response", "response_to": COMMAND, "success":
true|false, "error_message": "", "result": ..., "format": "json_v3"}`` (the configuration for
``get_config``, with the ``speed_of_sound`` the served reports were made with when the log says
it: :func:`served_config`; null otherwise). The served reports replay a Log (velocity lines by
:func:`undertow.io.a50_json.velocity_report_line`, the writer of the bag tools); commands change
nothing in what is served (the replayed dead reckoning is not reset), they are answered and
kept in ``A50Server.commands`` (and the session summary).
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time

import numpy as np

from ...io.a50_json import velocity_report_line
from ...log import Log
from .player import Faults, Manifest, PlayClock, Served

DEFAULT_PORT = 16171
#: the configuration answered to ``get_config`` (the A50's fields and defaults)
DEFAULT_CONFIG = {
    "speed_of_sound": 1475.0,
    "mounting_rotation_offset": 0.0,
    "acoustic_enabled": True,
    "dark_mode_enabled": False,
    "range_mode": "auto",
    "periodic_cycling_enabled": True,
}
COMMANDS = ("get_config", "set_config", "reset_dead_reckoning", "calibrate_gyro", "trigger_ping")


def served_config(log: Log) -> dict:
    """:data:`DEFAULT_CONFIG` with the ``speed_of_sound`` the served reports were made with
    (the log's ``dvl_sound_speed_m_s``, a simulated DVL's setting), when the log says it."""
    said = (log.metadata or {}).get("dvl_sound_speed_m_s")
    config = dict(DEFAULT_CONFIG)
    if isinstance(said, (int, float)) and math.isfinite(said) and said > 0:
        config["speed_of_sound"] = float(said)
    return config


MAX_COMMAND_BYTES = 64 * 1024
#: JSON structural characters: flipping one of them makes the line undecodable
_STRUCTURAL = frozenset(b'{}[]:,"')


def position_report_line(dr, i: int, ts_s: float) -> str:
    """Row ``i`` of a DeadReckoning stream as a json_v3 ``position_local`` line (angles in
    degrees, as the A50 sends them; a missing std is NaN)."""
    roll, pitch, yaw = np.rad2deg(np.asarray(dr.orientation[i], float))
    std = math.nan if dr.std is None else float(dr.std[i])
    x, y, z = (float(v) for v in dr.position[i])
    report = {
        "ts": float(ts_s),
        "x": x,
        "y": y,
        "z": z,
        "std": std,
        "roll": float(roll),
        "pitch": float(pitch),
        "yaw": float(yaw),
        "type": "position_local",
        "status": 0,
        "format": "json_v3",
    }
    return json.dumps(report)


def corrupt_line(line: bytes, rng: np.random.Generator) -> bytes:
    """``line`` with one JSON structural byte (``{}[]:,"``) flipped to a non-ASCII byte (XOR
    0x80): the line no longer decodes, and stays one line."""
    positions = [k for k, b in enumerate(line) if b in _STRUCTURAL]
    out = bytearray(line)
    k = positions[int(rng.integers(len(positions)))] if positions else 0
    out[k] ^= 0x80
    return bytes(out)


def response_line(command: str, success: bool = True, result=None, error: str = "") -> bytes:
    reply = {
        "type": "response",
        "response_to": command,
        "success": success,
        "error_message": error,
        "result": result,
        "format": "json_v3",
    }
    return (json.dumps(reply) + "\n").encode()


class _Client:
    """One TCP client: writes under a lock, a reader thread answering its commands."""

    def __init__(self, conn: socket.socket, server: A50Server) -> None:
        self.conn, self.server = conn, server
        self.lock = threading.Lock()
        self.closed = False
        conn.settimeout(2.0)
        self.thread = threading.Thread(target=self._read, name="a50-client", daemon=True)
        self.thread.start()

    def send(self, data: bytes) -> bool:
        with self.lock:
            if self.closed:
                return False
            try:
                self.conn.sendall(data)
                return True
            except OSError:
                self._close()
                return False

    def close(self) -> None:
        with self.lock:
            self._close()

    def _close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self.conn.close()

    def _read(self) -> None:
        pending = b""
        while not self.closed:
            try:
                chunk = self.conn.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                break
            if not chunk:
                break
            *lines, pending = (pending + chunk).split(b"\n")
            pending = pending[-MAX_COMMAND_BYTES:]
            for line in lines:
                if line.strip():
                    self.send(self.server.answer(line))
        self.close()


class A50Server:
    """The TCP side: listens on (``host``, ``port``; 0 = any free port), writes report lines to
    every client, answers commands; :meth:`set_down` closes every connection and refuses new
    ones until called again with False (a dropped link)."""

    def __init__(
        self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, config: dict | None = None
    ) -> None:
        self.host, self.port = host, int(port)
        self.config = dict(DEFAULT_CONFIG if config is None else config)
        self.commands: list[str] = []
        self.connections = 0
        self.down = False
        self._clients: list[_Client] = []
        self._lock = threading.Lock()
        self._listener: socket.socket | None = None
        self._closed = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def address(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    def open(self) -> A50Server:
        self._listen()
        self._thread = threading.Thread(target=self._accept, name="a50-accept", daemon=True)
        self._thread.start()
        return self

    def _listen(self) -> None:
        sock = socket.create_server((self.host, self.port))
        sock.settimeout(0.1)
        self.port = sock.getsockname()[1]
        self._listener = sock

    def _accept(self) -> None:
        while not self._closed.is_set():
            sock = self._listener
            if sock is None:
                self._reopen()
                continue
            try:
                conn, _ = sock.accept()
            except (TimeoutError, OSError):
                continue
            with self._lock:
                if self.down or self._closed.is_set():
                    conn.close()
                    continue
                self.connections += 1
                self._clients.append(_Client(conn, self))

    def _reopen(self) -> None:
        """Listen again once the drop is over (retried: the old socket may linger a moment)."""
        if not self.down:
            try:
                with self._lock:
                    if not self.down and self._listener is None:
                        self._listen()
                return
            except OSError:
                pass
        self._closed.wait(0.02)

    def clients(self) -> int:
        with self._lock:
            self._clients = [c for c in self._clients if not c.closed]
            return len(self._clients)

    def broadcast(self, data: bytes) -> int:
        """Write ``data`` to every client; the number written to."""
        with self._lock:
            clients = list(self._clients)
        return sum(c.send(data) for c in clients)

    def set_down(self, down: bool) -> None:
        """Down: close every connection and the listening socket (connections are refused);
        up again: the accept thread listens on the same port."""
        with self._lock:
            self.down = down
            if not down:
                return
            clients, self._clients = self._clients, []
            listener, self._listener = self._listener, None
        if listener is not None:
            try:
                listener.shutdown(socket.SHUT_RDWR)  # wakes a blocked accept at once
            except OSError:
                pass
            listener.close()
        for c in clients:
            c.close()

    def answer(self, line: bytes) -> bytes:
        """The response line to one command line."""
        try:
            obj = json.loads(line)
            command = obj.get("command") if isinstance(obj, dict) else None
        except (ValueError, UnicodeDecodeError, RecursionError):
            command = None
        if not isinstance(command, str):
            return response_line("", False, None, "could not parse the command")
        self.commands.append(command)
        if command not in COMMANDS:
            return response_line(command, False, None, f"unknown command '{command}'")
        if command == "set_config":
            params = obj.get("parameters")
            if not isinstance(params, dict) or not set(params) <= set(self.config):
                return response_line(command, False, None, "unknown configuration field")
            self.config.update(params)
        return response_line(command, True, dict(self.config) if command == "get_config" else None)

    def close(self) -> None:
        self._closed.set()
        self.set_down(True)
        if self._thread is not None:
            self._thread.join(1.0)


class A50Reports:
    """The A50 sink of the player: formats the log's DVL and dead-reckoning rows as report lines
    with the served clock, applies the faults and writes them through an :class:`A50Server`."""

    protocol = "a50"

    def __init__(
        self,
        server: A50Server,
        log: Log,
        manifest: Manifest,
        faults: Faults,
        rng: np.random.Generator,
    ) -> None:
        self.server, self.log = server, log
        self.clock: PlayClock | None = None  # set by the player
        self.manifest, self.faults, self.rng = manifest, faults, rng
        self._held: dict[str, tuple] = {}
        dvl = log.dvl
        if dvl is not None and len(dvl) > 1:
            dt = np.diff(dvl.t)
            self._time_ms = np.concatenate([[dt[0]], dt]) * 1e3
        else:
            self._time_ms = np.zeros(0 if dvl is None else len(dvl))

    def schedule(self, log: Log) -> dict[str, np.ndarray]:
        return {
            k: getattr(log, k).t
            for k in ("dvl", "dead_reckoning")
            if getattr(log, k) is not None and len(getattr(log, k))
        }

    def ready(self) -> bool:
        return not self.schedule(self.log) or self.server.clients() > 0

    def line(self, key: str, index: int, at: float) -> tuple[str, float]:
        """(report line, its sensor time s) of row ``index`` of ``key`` at playback time."""
        s = self.clock.sensor_time(at) + self.faults.jump(key, at - self.clock.t0)
        if key == "dvl":
            return velocity_report_line(self.log.dvl, index, self._time_ms[index], s), s
        return position_report_line(self.log.dead_reckoning, index, s), s

    def emit(self, key: str, index: int, at: float) -> None:
        text, s = self.line(key, index, at)
        payload = (text + "\n").encode()
        if key == "dvl":
            s = round(s * 1e6) * 1e-6  # time_of_validity is whole microseconds
        message = "velocity" if key == "dvl" else "position_local"
        entry = dict(
            protocol="a50",
            message=message,
            stream=key,
            index=index,
            t=at,
            at=at,
            sensor_time=s,
            payload=payload,
        )
        if self.server.down:
            self._add(entry, "dropped", 0)
            return
        f, rng = self.faults, self.rng
        if f.corrupt and rng.random() < f.corrupt:
            self._add(
                entry, "corrupt", self.server.broadcast(corrupt_line(payload[:-1], rng) + b"\n")
            )
            return
        if f.reorder and key not in self._held and rng.random() < f.reorder:
            self._held[key] = entry  # sent after the next report of this stream
            return
        self._add(entry, "", self.server.broadcast(payload))
        if f.duplicate and rng.random() < f.duplicate:
            self._add(entry, "duplicate", self.server.broadcast(payload))
        held = self._held.pop(key, None)
        if held is not None:
            self._add(held, "reordered", self.server.broadcast(held["payload"]))

    def flush(self) -> None:
        """Send what is still held back at the end of the log (late, but in order: no newer
        report of its stream was sent, so it is not tagged as reordered)."""
        for key in list(self._held):
            held = self._held.pop(key)
            self._add(held, "", self.server.broadcast(held["payload"]))

    def _add(self, entry: dict, fault: str, clients: int) -> None:
        self.manifest.add(Served(**entry, wall=time.time(), fault=fault, clients=clients))
