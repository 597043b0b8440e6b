"""A fake autopilot for the tests of `undertow live --autopilot`: a MAVLink peer on 127.0.0.1
that the test starts, built on pymavlink (the peer library that decodes what undertow sends).

It relays the virtual robot's telemetry (`undertow serve --mavlink udpout:...` sends to its UDP
port) to undertow's MAVLink link, over UDP (undertow listens, ``udpin``) or TCP (the peer
listens, undertow connects, ``tcp:HOST:PORT``), as system 1 component 1; it decodes every
message undertow sends back (kept in ``received``, with the peer's receive time) and answers as
ArduPilot does (GCS_Common.cpp, GCS_Param.cpp):

- PARAM_REQUEST_READ -> PARAM_VALUE of a known name (no answer for an unknown one);
- PARAM_SET -> the parameter takes the value, PARAM_VALUE echoes it;
- MAV_CMD_REQUEST_MESSAGE(GPS_GLOBAL_ORIGIN) -> GPS_GLOBAL_ORIGIN when it has an origin;
- SET_GPS_GLOBAL_ORIGIN -> taken only when it has none (then GPS_GLOBAL_ORIGIN);
- COMMAND_LONG -> COMMAND_ACK; SET_MESSAGE_INTERVAL of EKF_STATUS_REPORT starts sending it.

``extra`` sends a message as another component (the Water Linked extension: 255/0).
"""

from __future__ import annotations

import socket
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as m

DEFAULT_PARAMS = {
    "AHRS_EKF_TYPE": 3, "EK3_ENABLE": 1, "VISO_TYPE": 0, "GPS1_TYPE": 1, "EK3_SRC1_POSXY": 3,
    "EK3_SRC1_VELXY": 3, "EK3_SRC1_POSZ": 1, "EK3_SRC1_VELZ": 3, "EK3_SRC1_YAW": 1,
    "VISO_QUAL_MIN": 0, "VISO_POS_M_NSE": 0.2, "VISO_ORIENT": 0, "VISO_POS_X": 0.0,
    "VISO_POS_Y": 0.0, "VISO_POS_Z": 0.0, "VISO_SCALE": 1.0, "VISO_DELAY_MS": 10,
    "VISO_YAW_M_NSE": 0.2, "VISO_VEL_M_NSE": 0.1, "EK3_SRC_OPTIONS": 1,
    "EK3_VIS_VERR_MIN": 0.1, "EK3_VIS_VERR_MAX": 0.9,
}  # fmt: skip


class FakeAutopilot:
    """The peer of the module docstring. ``transport``: "udp" (send to undertow's udpin port
    ``undertow_port``) or "tcp" (listen; :attr:`tcp_address` for undertow's --mavlink)."""

    def __init__(self, transport: str = "udp", undertow_port: int | None = None, *,
                 params=None, origin=None, heartbeat_hz: float = 0.0) -> None:  # fmt: skip
        self.transport = transport
        self.params = dict(DEFAULT_PARAMS if params is None else params)
        self.origin = origin  # (lat_e7, lon_e7, alt_mm) or None
        self.mav = m.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = m.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[tuple[float, object]] = []
        self.lock = threading.Lock()
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(("127.0.0.1", 0))
        self.udp.settimeout(0.05)
        self.telemetry_port = self.udp.getsockname()[1]  # serve's --mavlink udpout goes here
        self.undertow = None if undertow_port is None else ("127.0.0.1", int(undertow_port))
        self.tcp_server = self.tcp = None
        if transport == "tcp":
            self.tcp_server = socket.socket()
            self.tcp_server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.tcp_server.bind(("127.0.0.1", 0))
            self.tcp_server.listen(1)
            self.tcp_server.settimeout(0.05)
        self.ekf_streaming = False  # EKF_STATUS_REPORT and LOCAL_POSITION_NED asked for
        self.heartbeat_hz = float(heartbeat_hz)
        self.telemetry = m.MAVLink(None)  # reads the relayed telemetry: the autopilot's clock
        self.telemetry.robust_parsing = True
        self.boot_ms = None
        self.nav: tuple[float, tuple] | None = None  # (receive time, x y z) of the last fix
        self._next_report = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def tcp_address(self) -> str:
        return f"tcp:127.0.0.1:{self.tcp_server.getsockname()[1]}"

    def start(self) -> FakeAutopilot:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for s in (self.udp, self.tcp, self.tcp_server):
            if s is not None:
                s.close()

    # -- what undertow sent -------------------------------------------------------------------
    def messages(self, name: str | None = None) -> list:
        with self.lock:
            return [msg for _, msg in self.received if name is None or msg.get_type() == name]

    def times(self, name: str) -> list[float]:
        with self.lock:
            return [t for t, msg in self.received if msg.get_type() == name]

    # -- sending -------------------------------------------------------------------------------
    def send(self, msg, mav=None) -> None:
        self.write(bytes(msg.pack(mav or self.mav)))
        (mav or self.mav).seq = ((mav or self.mav).seq + 1) % 256

    def extra(self, msg, sysid: int = 255, compid: int = 0) -> None:
        """Send ``msg`` as another component."""
        self.send(msg, m.MAVLink(None, srcSystem=sysid, srcComponent=compid))

    def write(self, data: bytes) -> None:
        try:
            if self.transport == "tcp":
                if self.tcp is not None:
                    self.tcp.sendall(data)
            elif self.undertow is not None:
                self.udp.sendto(data, self.undertow)
        except OSError:
            pass

    # -- the loop ------------------------------------------------------------------------------
    def _run(self) -> None:
        next_beat = 0.0
        while not self._stop.is_set():
            self._accept()
            self._relay()
            self._read_tcp()
            now = time.monotonic()
            if self.ekf_streaming and now >= self._next_report:
                self._next_report = now + 0.5
                self._report(now)
            if self.heartbeat_hz and now >= next_beat:
                next_beat = now + 1.0 / self.heartbeat_hz
                self.send(m.MAVLink_heartbeat_message(12, 3, 0, 0, 4, 3))

    def _accept(self) -> None:
        if self.tcp_server is None or self.tcp is not None:
            return
        try:
            self.tcp, _ = self.tcp_server.accept()
            self.tcp.settimeout(0.0)
        except (TimeoutError, OSError):
            pass

    def _relay(self) -> None:
        try:
            data, addr = self.udp.recvfrom(65535)
        except (TimeoutError, OSError):
            return
        if self.undertow is not None and addr[1] == self.undertow[1] and self.transport == "udp":
            return self._take(data)
        self.write(data)  # the robot's telemetry, on to undertow
        for msg in self.telemetry.parse_buffer(data) or ():
            if msg.get_type() == "ATTITUDE":
                self.boot_ms = msg.time_boot_ms

    def _read_tcp(self) -> None:
        if self.tcp is None:
            return
        try:
            data = self.tcp.recv(65535)
        except (BlockingIOError, OSError):
            return
        if data:
            self._take(data)

    def _take(self, data: bytes) -> None:
        now = time.monotonic()
        for msg in self.parser.parse_buffer(data) or ():
            if msg.get_type() == "BAD_DATA":
                continue
            with self.lock:
                self.received.append((now, msg))
            if msg.get_type() in ("ODOMETRY", "VISION_POSITION_ESTIMATE"):
                self.nav = (now, (msg.x, msg.y, msg.z))
            self._answer(msg)

    def _answer(self, msg) -> None:
        name = msg.get_type()
        if name == "PARAM_REQUEST_READ":
            pid = msg.param_id.rstrip("\0") if isinstance(msg.param_id, str) else msg.param_id
            if pid in self.params:
                self._param_value(pid)
        elif name == "PARAM_SET":
            pid = msg.param_id.rstrip("\0")
            if pid in self.params:
                self.params[pid] = msg.param_value
                self._param_value(pid)
        elif name == "COMMAND_LONG":
            self._command(msg)
        elif name == "SET_GPS_GLOBAL_ORIGIN" and self.origin is None:
            self.origin = (msg.latitude, msg.longitude, msg.altitude)
            self.send(m.MAVLink_gps_global_origin_message(*self.origin))

    def _param_value(self, pid: str) -> None:
        ptype = (
            m.MAV_PARAM_TYPE_REAL32
            if isinstance(self.params[pid], float)
            else m.MAV_PARAM_TYPE_INT8
        )
        self.send(m.MAVLink_param_value_message(pid.encode(), float(self.params[pid]), ptype,
                                                len(self.params), 65535))  # fmt: skip

    def _command(self, msg) -> None:
        self.send(m.MAVLink_command_ack_message(msg.command, 0))
        if msg.command == m.MAV_CMD_REQUEST_MESSAGE and int(msg.param1) == 49 and self.origin:
            self.send(m.MAVLink_gps_global_origin_message(*self.origin))
        if msg.command == m.MAV_CMD_SET_MESSAGE_INTERVAL and int(msg.param1) in (32, 193):
            self.ekf_streaming = True

    def _report(self, now: float) -> None:
        """What a fusing EKF would say: position flags while fixes came in the last second
        (attitude, velocities, horizontal relative and absolute, vertical), else attitude and
        constant-position mode; LOCAL_POSITION_NED the last fix, at the autopilot's time."""
        fusing = self.nav is not None and now - self.nav[0] < 1.0
        flags = 0x3F if fusing else 0x01 | 0x20 | 0x80
        self.send(m.MAVLink_ekf_status_report_message(flags, 0.1, 0.2, 0.1, 0.05, 0.0))
        if self.nav is not None and self.boot_ms is not None:
            self.send(m.MAVLink_local_position_ned_message(self.boot_ms, *self.nav[1], 0, 0, 0))
