"""A virtual Blue Robotics Ping1D on UDP, answering ``brping`` as the echosounder does.

The Ping protocol (Blue Robotics ping-protocol): frames ``B`` ``R``, payload length (u16),
message id (u16), source and destination device ids (u8), payload, and a u16 checksum = the sum
of every preceding byte mod 2^16. A host asks for a message either with
``general_request`` (id 6, payload ``requested_id``; ``brping.PingDevice.request``) or, the
legacy way ``brping.Ping1D.legacyRequest`` uses, with an empty frame carrying the wanted id. The
device answers with that message; setters (``set_*``) are acknowledged (``ack``, id 1), unknown
ids refused (``nack``, id 2). Frames are packed with brping's own message definitions
(``brping.pingmessage.PingMessage``, ``brping.definitions``).

``distance`` (id 1212) and ``distance_simple`` (1211) answer the log's newest range at the time
of the request (playback time, :class:`~undertow.sim.robot.player.PlayClock`): distance =
round(1000 r) mm, confidence = round(100 c) % (255, out of the 0-100 range, when the log's
confidence is NaN; a NaN range is distance 0, confidence 0, the Ping's "no target"),
``ping_number`` = the row's number since playback began (1, 2, ...: repeated while no new ping
happened, as a Ping polled faster than it pings). Before the first range: distance 0,
confidence 0, ping_number 0. The Ping has no clock: nothing in the reply says when it measured.
"""

from __future__ import annotations

import contextlib
import io
import math
import socket
import threading
import time

import numpy as np

from ...io.ping import distance_fields, load_brping
from ...log import Log
from .player import Faults, Manifest, PlayClock, Served, flip_one_byte

DEFAULT_PORT = 9090
#: field values of the informational messages a Ping1D answers (others: zeros)
DEVICE_FIELDS = {
    "protocol_version": {"version_major": 1, "version_minor": 0, "version_patch": 0},
    "device_information": {
        "device_type": 1,
        "device_revision": 1,
        "firmware_version_major": 3,
        "firmware_version_minor": 29,
    },
    "firmware_version": {
        "device_type": 1,
        "device_model": 1,
        "firmware_version_major": 3,
        "firmware_version_minor": 29,
    },
    "general_info": {
        "firmware_version_major": 3,
        "firmware_version_minor": 29,
        "voltage_5": 5000,
        "ping_interval": 100,
        "gain_setting": 0,
        "mode_auto": 1,
    },
    "voltage_5": {"voltage_5": 5000},
    "speed_of_sound": {"speed_of_sound": 1_500_000},
    "mode_auto": {"mode_auto": 1},
    "ping_interval": {"ping_interval": 100},
    "ping_enable": {"ping_enabled": 1},
    "transmit_duration": {"transmit_duration": 100},
    "processor_temperature": {"processor_temperature": 4000},
    "pcb_temperature": {"pcb_temperature": 3500},
}


def corrupt_frame(frame: bytes, rng: np.random.Generator) -> bytes:
    """``frame`` with one payload or checksum byte changed: the checksum no longer matches
    (a one-byte change alters the byte sum by 1..255, never 0 mod 2^16), the length is kept."""
    return flip_one_byte(frame, 8, rng)


class Ping1DServer:
    """The UDP Ping1D on (``host``, ``port``; 0 = any free port), serving ``log.sonar``."""

    protocol = "ping1d"

    def __init__(
        self,
        log: Log,
        manifest: Manifest,
        faults: Faults,
        rng: np.random.Generator,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
    ) -> None:
        _, self.defs, self.pm = load_brping()
        self.log, self.manifest = log, manifest
        self.clock: PlayClock | None = None  # set by the player
        self.faults, self.rng = faults, rng
        self.host, self.port = host, int(port)
        sonar = log.sonar
        self.times = np.zeros(0) if sonar is None else np.asarray(sonar.t, float)
        self.requests = 0
        self._parsers: dict = {}
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None

    @property
    def address(self) -> str:
        return f"udp://{self.host}:{self.port}"

    def schedule(self, log: Log) -> dict[str, np.ndarray]:
        # the Ping answers requests and pushes nothing; its rows still set the playback span
        return {"sonar": self.times} if len(self.times) else {}

    def emit(self, key: str, index: int, at: float) -> None:
        return None

    def ready(self) -> bool:
        return len(self.times) == 0 or self.requests > 0

    def open(self) -> Ping1DServer:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((self.host, self.port))
        sock.settimeout(0.1)
        self.port = sock.getsockname()[1]
        self._sock = sock
        self._thread = threading.Thread(target=self._serve, name="ping1d-server", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        if self._sock is not None:
            self._sock.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(65536)
            except (TimeoutError, OSError):
                continue
            parser = self._parsers.setdefault(addr, self.pm.PingParser())
            if len(self._parsers) > 64:  # bounded: forget the oldest clients
                self._parsers.pop(next(iter(self._parsers)))
            out = self.answer(parser, data)
            if out:
                try:
                    self._sock.sendto(out, addr)
                except OSError:
                    pass

    def answer(self, parser, data: bytes) -> bytes:
        """The reply frames to the requests in ``data`` (parsed with ``parser``)."""
        replies = b""
        with contextlib.redirect_stdout(io.StringIO()):  # brping prints on unknown ids
            for byte in data:
                if parser.parse_byte(byte) != self.pm.PingParser.NEW_MESSAGE:
                    continue
                msg = parser.rx_msg
                wanted = msg.message_id
                if wanted == self.defs.COMMON_GENERAL_REQUEST:
                    wanted = getattr(msg, "requested_id", None)
                self.requests += 1
                replies += self.reply(wanted)
        return replies

    def reply(self, wanted) -> bytes:
        defs = self.defs
        if wanted in (defs.PING1D_DISTANCE, defs.PING1D_DISTANCE_SIMPLE):
            return self._distance(wanted)
        spec = defs.payload_dict_all.get(wanted) if isinstance(wanted, int) else None
        if spec is None or wanted in (
            defs.COMMON_GENERAL_REQUEST,
            defs.COMMON_ACK,
            defs.COMMON_NACK,
        ):
            return self._pack(
                defs.COMMON_NACK,
                nacked_id=int(wanted or 0) & 0xFFFF,
                nack_message=bytearray(b"unknown message"),
            )
        if spec["name"].startswith(("set_", "goto_", "continuous_")):
            return self._pack(defs.COMMON_ACK, acked_id=wanted)
        return self._pack(wanted, **DEVICE_FIELDS.get(spec["name"], {}))

    def _pack(self, msg_id: int, **fields) -> bytes:
        msg = self.pm.PingMessage(msg_id)
        for name, value in fields.items():
            setattr(msg, name, value)
        msg.src_device_id = 1
        msg.pack_msg_data()
        return bytes(msg.msg_data)

    def _distance(self, wanted: int) -> bytes:
        if self.clock is None or len(self.times) == 0:
            at, (k, t, lap) = math.nan, (-1, math.nan, 0)
        else:
            at = self.clock.now()
            k, t, lap = self.clock.latest(self.times, at)
        sonar = self.log.sonar
        if k < 0:
            distance, confidence, number = 0, 0, 0
        else:
            c = math.nan if sonar.confidence is None else float(sonar.confidence[k])
            distance, confidence = distance_fields(float(sonar.range[k]), c)
            number = lap * len(self.times) + k + 1
        fields = {"distance": distance, "confidence": confidence}
        if wanted == self.defs.PING1D_DISTANCE:
            scan = int(round(1000 * sonar.max_range)) if sonar is not None else 0
            fields.update(ping_number=number, transmit_duration=100, scan_length=scan)
        frame = self._pack(wanted, **fields)
        fault = ""
        if self.faults.corrupt and self.rng.random() < self.faults.corrupt:
            fault, out = "corrupt", corrupt_frame(frame, self.rng)
        else:
            out = frame
        self.manifest.add(
            Served(
                "ping1d",
                "distance" if wanted == self.defs.PING1D_DISTANCE else "distance_simple",
                "sonar" if k >= 0 else "",
                k,
                t,
                at,
                math.nan,
                time.time(),
                fault,
                -1,
                frame,
            )
        )
        return out
