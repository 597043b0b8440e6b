"""ArduSub SITL for the tests marked ``sitl``: the real autopilot (ArduPilot's firmware built
for this machine, in the project's shared folder ``../shared/tools/ardusub``; its README says
how it was built and its quirks) started in a temporary folder, configured for external
navigation, rebooted, its EKF origin set, with two MAVLink clients:

- ``sitl.sender`` (SERIAL0): for whoever sends external navigation (the test's pymavlink
  sender, or ``undertow live --autopilot --mavlink <sitl.sender_address>``);
- ``sitl.monitor`` (SERIAL1): a second client that records what the autopilot itself says
  (STATUSTEXT, EKF_STATUS_REPORT, LOCAL_POSITION_NED, GPS_GLOBAL_ORIGIN) in a thread.

Transport ``udp`` (default): SITL's serial ports are ``udpclient:127.0.0.1:PORT`` and the
clients listen there (``udpin:127.0.0.1:PORT``), so every MAVLink socket is on 127.0.0.1 and
the SITL runs without waiting for a client; ``tcp``: SITL's own TCP servers on 5760 + 10 N
(SERIAL0, which waits for a client before running) and 5762 + 10 N, which bind all interfaces.
Either way SITL's RC input listens on UDP 5501 + 10 N on all interfaces (its HAL binds it so).
The instance N is chosen with free ports. Set UNDERTOW_ARDUSUB to use another build folder.
"""

from __future__ import annotations

import os
import random
import shutil
import socket
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

#: the parameters that made the SITL's EKF3 take external navigation (its README), and the
#: ones that need the reboot among them (VISO_TYPE, GPS1_TYPE; EK3_SRC1_* because EKF3 sizes its
#: external-navigation buffers at boot)
EXTNAV_PARAMS = {
    "GPS1_TYPE": 0,
    "VISO_TYPE": 1,
    "EK3_SRC1_POSXY": 6,
    "EK3_SRC1_VELXY": 6,
    "EK3_SRC1_POSZ": 1,
    "EK3_SRC1_VELZ": 0,
    "EK3_SRC1_YAW": 1,
}


def find_ardusub() -> Path | None:
    """The folder holding the ``ardusub`` binary and ``sub.parm``, or None."""
    env = os.environ.get("UNDERTOW_ARDUSUB")
    if env:  # the one place to look when given
        candidates = [Path(env)]
    else:
        here = Path(__file__).resolve().parent
        candidates = [p / "shared" / "tools" / "ardusub" for p in here.parents]
        candidates.append(Path("/work/shared/tools/ardusub"))
    for folder in candidates:
        if (folder / "ardusub").is_file() and os.access(folder / "ardusub", os.X_OK):
            return folder
    return None


def _free(port: int, kind: int) -> bool:
    s = socket.socket(socket.AF_INET, kind)
    try:
        s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def free_instance(rng: random.Random | None = None) -> int:
    """An instance N whose SITL ports (TCP 5760-5763 + 10 N, UDP 5501 + 10 N and the client
    ports 15760-15762 + 10 N) are free now."""
    rng = rng or random.Random()
    for _ in range(200):
        n = rng.randrange(20, 400)
        tcp = [5760 + 10 * n + k for k in range(4)]
        udp = [5501 + 10 * n] + [15760 + 10 * n + k for k in range(3)]
        if all(_free(p, socket.SOCK_STREAM) for p in tcp) and all(
            _free(p, socket.SOCK_DGRAM) for p in udp
        ):
            return n
    raise RuntimeError("no free SITL instance found")


@dataclass
class Heard:
    """What the monitor heard: (monotonic time, message) per message, in order."""

    messages: list = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, t: float, msg) -> None:
        with self.lock:
            self.messages.append((t, msg))

    def of(self, *kinds: str, since: float = -1e18) -> list:
        with self.lock:
            return [(t, m) for t, m in self.messages if m.get_type() in kinds and t >= since]

    def texts(self, since: float = -1e18) -> list[tuple[float, str]]:
        return [(t, m.text) for t, m in self.of("STATUSTEXT", since=since)]

    def first_text(self, fragment: str, since: float = -1e18) -> float | None:
        return next((t for t, s in self.texts(since) if fragment in s), None)


class Sitl:
    """One ArduSub SITL process (module docstring); use as a context manager. Times are
    ``time.monotonic()``; ``boot`` is when the configured firmware came back from its
    reboot."""

    def __init__(self, folder: Path, workdir: Path, transport: str = "udp", speedup: int = 1):
        self.folder, self.workdir = Path(folder), Path(workdir)
        self.transport = transport
        self.speedup = int(speedup)
        self.instance = free_instance()
        self.process: subprocess.Popen | None = None
        self.sender = self.monitor = None
        self.heard = Heard()
        self.boot = self.ekf_ready = self.origin_time = float("nan")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # addresses ----------------------------------------------------------------------------
    def _port(self, serial: int) -> int:
        """SERIALk's port: ours (udp) or SITL's TCP server (5760, 5762, 5763 + 10 N)."""
        if self.transport == "udp":
            return 15760 + 10 * self.instance + serial
        return (5760, 5762, 5763)[serial] + 10 * self.instance

    @property
    def sender_address(self) -> str:
        """The pymavlink address a sender connects to (what ``undertow live --mavlink`` takes)."""
        kind = "udpin" if self.transport == "udp" else "tcp"
        return f"{kind}:127.0.0.1:{self._port(0)}"

    @property
    def monitor_address(self) -> str:
        kind = "udpin" if self.transport == "udp" else "tcp"
        return f"{kind}:127.0.0.1:{self._port(1)}"

    # process ------------------------------------------------------------------------------
    def _argv(self) -> list[str]:
        argv = [
            str(self.folder / "ardusub"),
            "--model",
            "vectored",
            "--speedup",
            str(self.speedup),
            "--defaults",
            str(self.folder / "sub.parm"),
            f"-I{self.instance}",
            "--sim-address=127.0.0.1",
        ]
        if self.transport == "udp":  # SERIAL2 too, so that no TCP server is opened
            for k in (0, 1, 2):
                argv += [f"--serial{k}", f"udpclient:127.0.0.1:{self._port(k)}"]
        return argv

    def start(self) -> Sitl:
        self.workdir.mkdir(parents=True, exist_ok=True)
        log = (self.workdir / "sitl.out").open("w")
        if self.transport == "udp":  # listen first: SITL sends as soon as it runs
            self.sender = self._connect(self.sender_address)
            self.monitor = self._connect(self.monitor_address)
        self.process = subprocess.Popen(
            self._argv(), cwd=self.workdir, stdout=log, stderr=subprocess.STDOUT
        )
        if self.transport == "tcp":
            self.sender = self._connect(self.sender_address, retry_s=10.0)
        self._wait_fresh(self.sender, 20.0)
        return self

    @staticmethod
    def _connect(address: str, retry_s: float = 0.0):
        from pymavlink import mavutil

        deadline = time.monotonic() + retry_s
        while True:
            try:  # one attempt per connection object: pymavlink's own TCP retries reuse a
                # socket whose connect was refused, which then fails forever on Linux
                return mavutil.mavlink_connection(
                    address, source_system=255, source_component=190, retries=0
                )
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        for conn in (self.sender, self.monitor):
            if conn is not None:
                try:
                    conn.close()
                except OSError:
                    pass
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()  # by its pid
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)

    def __enter__(self) -> Sitl:
        try:
            return self.start()
        except BaseException:
            self.stop()  # never leave the process behind
            raise

    def __exit__(self, *exc) -> None:
        self.stop()

    # configuration ------------------------------------------------------------------------
    def set_param(self, name: str, value: float, timeout: float = 3.0) -> float:
        """PARAM_SET and wait for the PARAM_VALUE echo; the value the autopilot stored."""
        conn = self.sender
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            conn.mav.param_set_send(1, 1, name.encode(), float(value), 9)
            reply = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if reply is not None and reply.param_id == name:
                return reply.param_value
        raise TimeoutError(f"SITL did not echo {name}")

    def reboot(self, timeout: float = 20.0) -> None:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN; back when the new process sends (a message with a
        small time_boot_ms: messages of the old one may still be queued)."""
        conn = self.sender
        conn.mav.command_long_send(1, 1, 246, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
        if ack is None or ack.result != 0:
            raise RuntimeError(f"SITL refused the reboot: {ack}")
        time.sleep(0.5)
        if self.transport == "tcp":  # the listening sockets went away with the old process
            conn.close()
            self.sender = self._connect(self.sender_address, retry_s=10.0)
        self._wait_fresh(self.sender, timeout)
        self.boot = time.monotonic()

    @staticmethod
    def _wait_fresh(conn, timeout: float) -> None:
        """Until ``conn`` receives a message of a process booted less than 5 s ago (and so
        replies to it: a udpin link answers the last sender)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = conn.recv_match(type=["ATTITUDE", "SYSTEM_TIME"], blocking=True, timeout=0.5)
            if msg is not None and msg.time_boot_ms < 5000:
                return
        raise TimeoutError("SITL did not come back")

    def command(self, conn, command: int, *params: float, tries: int = 5):
        """COMMAND_LONG until its COMMAND_ACK arrives; the ack."""
        args = (list(params) + [0.0] * 7)[:7]
        for _ in range(tries):
            conn.mav.command_long_send(1, 1, command, 0, *args)
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.2)
                if ack is not None and ack.command == command:
                    return ack
        raise TimeoutError(f"SITL did not acknowledge command {command}")

    def start_monitor(self, rates_hz: dict[int, float]) -> None:
        """Connect the second client, ask it for ``rates_hz`` (message id -> Hz) and record
        everything it hears in a thread."""
        if self.monitor is None:
            self.monitor = self._connect(self.monitor_address, retry_s=10.0)
        self._wait_fresh(self.monitor, 20.0)
        for msg_id, hz in rates_hz.items():
            self.command(self.monitor, 511, msg_id, 1e6 / hz)
        self._thread = threading.Thread(target=self._listen, name="sitl-monitor", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            msg = self.monitor.recv_match(blocking=True, timeout=0.05)
            if msg is not None and msg.get_srcSystem() == 1:
                self.heard.add(time.monotonic(), msg)

    def wait_text(self, fragment: str, timeout: float, since: float = -1e18) -> float:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            t = self.heard.first_text(fragment, since)
            if t is not None:
                return t
            time.sleep(0.05)
        raise TimeoutError(f"SITL never said {fragment!r} (heard: {self.heard.texts()[-8:]})")

    def set_origin(self, lat: float, lon: float, alt_m: float = 0.0, timeout: float = 10.0):
        """SET_GPS_GLOBAL_ORIGIN until the autopilot says "EKF3 IMU0 origin set" (the EKF
        refuses an origin before it runs); the GPS_GLOBAL_ORIGIN it replied on the sender's
        link (None if that reply was lost)."""
        deadline = time.monotonic() + timeout
        lat_e7, lon_e7 = int(round(lat * 1e7)), int(round(lon * 1e7))
        while time.monotonic() < deadline:
            sent = time.monotonic()
            self.sender.mav.set_gps_global_origin_send(1, lat_e7, lon_e7, int(alt_m * 1e3), 0)
            reply = self.sender.recv_match(type="GPS_GLOBAL_ORIGIN", blocking=True, timeout=0.5)
            confirmed = self.heard.first_text("EKF3 IMU0 origin set", since=sent)
            if confirmed is not None or reply is not None:
                self.origin_time = confirmed if confirmed is not None else time.monotonic()
                return reply
        raise TimeoutError("SITL never confirmed the EKF origin")

    def configure(self, params: dict[str, float], origin=(47.37, 8.54)) -> None:
        """Set ``params`` (and 921600 baud on the two links: SITL throttles its streams to the
        serial port's baud rate, 57600 by default on SERIAL1), reboot, start the monitor, wait
        for EKF3's tilt alignment, set the origin."""
        for name, value in {"SERIAL0_BAUD": 921, "SERIAL1_BAUD": 921, **params}.items():
            self.set_param(name, value)
        self.reboot()
        self.start_monitor({193: 10.0, 32: 10.0})
        self.ekf_ready = self.wait_text("EKF3 IMU0 tilt alignment complete", 30.0)
        self.set_origin(*origin)


def copy_log(sitl: Sitl, dest: Path) -> None:
    """Keep the SITL's output next to a failing test's files (its stdout, nothing else)."""
    out = sitl.workdir / "sitl.out"
    if out.is_file():
        shutil.copy(out, dest)
