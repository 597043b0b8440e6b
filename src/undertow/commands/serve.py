"""The virtual robot (``undertow serve``): a log or a simulated scenario played as live sensors.

:func:`serve` reads a log (bag, A50 JSON log, ``.tlog``) or simulates a scenario (a built-in
name or a scenario YAML file), then :meth:`ServeSession.start` serves it on this machine, in
real time x ``rate``: the DVL and its dead reckoning as a Water Linked A50 (TCP JSON,
``dvl_port``), the sonar as a Ping1D (UDP, ``ping_port``), IMU and pressure as an ArduSub
autopilot (MAVLink to ``mavlink``), with optional :class:`~undertow.sim.robot.player.Faults`;
with ``autopilot`` the MAVLink link also carries a virtual ArduSub autopilot that consumes
external navigation as EKF3 does (:mod:`undertow.sim.robot.autopilot`).
Sensor clocks and timing: :mod:`undertow.sim.robot.player`. Everything binds 127.0.0.1 unless
another ``host`` is given. Every message served is in :attr:`ServeSession.manifest`::

    from undertow.commands.serve import serve

    with serve("calm", rate=10, dvl_port=0, ping_port=0) as session:   # 0: free ports
        print(session.endpoints.live_options())
        session.wait()
    print(session.summary())
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util.clocks import ScaledClock, replay_anchor
from ..errors import ConfigError
from ..io import detect_format
from ..log import Log
from ..sim import list_scenarios, load_scenario, simulate
from ..sim.robot import Faults, Manifest, Player
from ..sim.robot.a50 import A50Reports, A50Server, served_config
from ..sim.robot.autopilot import VirtualAutopilot, load_param_file
from ..sim.robot.autopilot_link import AutopilotLink, log_attitude, log_depth
from ..sim.robot.decode import served_log
from ..sim.robot.mavlink import DEFAULT_ADDRESS, MavlinkSender
from ..sim.robot.ping1d import Ping1DServer
from .common import load_log


def load_source(source, duration: float | None = None, topics=None) -> Log:
    """The log to serve: a Log (or a simulation result) as is, a log file read, or a scenario
    (built-in name or YAML file) simulated; cut to its first ``duration`` s when given."""
    log = source.log if hasattr(source, "log") and hasattr(source, "floor_cloud") else source
    if not isinstance(log, Log):
        text = str(source)
        path = Path(text)
        if path.suffix.lower() in (".yaml", ".yml") or (
            text in list_scenarios() and not path.exists()
        ):
            log = simulate(load_scenario(text)).log
        elif path.exists():
            detect_format(path)  # one line for a file that is no log
            log = load_log(path, topics)
        else:
            raise ConfigError(
                f"{text}: no such log file and not a scenario (built-ins: "
                f"{', '.join(list_scenarios())})"
            )
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise ConfigError(f"--duration: expected a positive number of seconds, got {duration}")
        t0 = log.time_span[0]
        log = log.replace(**{n: s.select(s.t < t0 + duration) for n, s in log.streams().items()})
    return log


@dataclass(frozen=True)
class Endpoints:
    """Where the virtual sensors are: ``dvl`` (tcp://HOST:PORT), ``sonar`` (udp://HOST:PORT),
    ``mavlink`` (the address sent to) and ``mavlink_listen`` (what a receiver listens on);
    None for a sensor not served."""

    dvl: str | None = None
    sonar: str | None = None
    mavlink: str | None = None
    mavlink_listen: str | None = None

    def live_options(self) -> list[str]:
        """The ``undertow live`` options that connect to these sensors."""
        out = []
        for option, value in (
            ("--dvl", self.dvl),
            ("--sonar", self.sonar),
            ("--mavlink", self.mavlink_listen),
        ):
            if value:
                out += [option, value]
        return out


def _listen_address(address: str) -> str | None:
    kind, _, rest = address.partition(":")
    return {"udpout": f"udpin:{rest}", "tcpin": f"tcp:{rest}"}.get(kind)


@dataclass(eq=False)
class ServeSession:
    """A served log: :meth:`start`, :meth:`wait`, :meth:`stop` (also a context manager).
    ``endpoints`` are known once the servers are open (after :meth:`open`/:meth:`start`)."""

    log: Log
    player: Player
    manifest: Manifest
    faults: Faults
    rate: float
    loop: bool
    a50: A50Server | None = None
    ping: Ping1DServer | None = None
    mavlink: MavlinkSender | None = None
    autopilot: AutopilotLink | None = None
    endpoints: Endpoints = field(default_factory=Endpoints)
    _open: bool = False

    def open(self) -> ServeSession:
        """Bind the servers (ports known, playback not started); closes them on failure."""
        if self._open:
            return self
        try:
            for server in (self.a50, self.ping, self.mavlink):
                if server is not None:
                    server.open()
        except OSError as exc:
            self.close()
            raise ConfigError(f"serve: cannot open a server: {exc.strerror or exc}") from None
        self._open = True
        self.endpoints = Endpoints(
            self.a50.address if self.a50 else None,
            self.ping.address if self.ping else None,
            self.mavlink.address if self.mavlink else None,
            _listen_address(self.mavlink.address) if self.mavlink else None,
        )
        return self

    def start(self) -> ServeSession:
        self.open()
        if self.autopilot is not None and self.autopilot._thread is None:
            self.autopilot.start()
        self.player.start()
        return self

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the playback ends (never with ``loop``); True when it did. A failure of the
        player (a bug) is raised here."""
        done = self.player.done.wait(timeout)
        if self.player.error is not None:
            raise self.player.error
        if self.autopilot is not None and self.autopilot.error is not None:
            raise self.autopilot.error
        return done

    @property
    def done(self) -> bool:
        return self.player.done.is_set()

    def close(self) -> None:
        for server in (self.a50, self.ping, self.mavlink):
            if server is not None:
                server.close()

    def stop(self) -> dict:
        """Stop playing, close the servers; the :meth:`summary`."""
        self.player.stop()
        if self.autopilot is not None:
            self.autopilot.stop()
        self.close()
        return self.summary()

    def __enter__(self) -> ServeSession:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def clock(self) -> ScaledClock:
        """An arrival clock for links reading this session: c(w) = A + rate (w - A) (A: the
        hour's start), which equals the served sensor clock (epoch + playback time) with the
        default epoch; ``undertow live --time-scale rate`` uses the same clock."""
        if not self.player.clock.started.wait((self.player.wait_for_clients or 0.0) + 5.0):
            raise ConfigError("serve: the playback has not started (call start() first)")
        return ScaledClock(self.rate, start=replay_anchor(self.player.clock.wall0))

    @property
    def epoch(self) -> float | None:
        return self.player.clock.epoch

    def served_log(self, mavlink=None, faulty: bool = False) -> Log:
        """What was served, as a Log in playback time
        (:func:`~undertow.sim.robot.decode.served_log`)."""
        return served_log(self.manifest.select(), mavlink, faulty)

    def summary(self) -> dict:
        """Endpoints, timing and what was served (counts per message and fault)."""
        clock = self.player.clock
        return {
            "source": self.log.source,
            "endpoints": {k: v for k, v in self.endpoints.__dict__.items() if v},
            "rate": self.rate,
            "loop": self.loop,
            "span_s": self.player.span,
            "laps": self.player.laps,
            "played_s": self.player.position - clock.t0,
            "epoch": clock.epoch,
            "t0": clock.t0,
            "faults": self.faults.to_dict(),
            "a50_commands": list(self.a50.commands) if self.a50 else [],
            "a50_connections": self.a50.connections if self.a50 else 0,
            "ping_requests": self.ping.requests if self.ping else 0,
            "autopilot": self.autopilot.autopilot.summary() if self.autopilot else None,
            **self.manifest.summary(),
        }


def _port(value, name: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or int(value) != value or not 0 <= int(value) < 65536:
        raise ConfigError(f"{name}: expected a port number 0..65535 (0: any free), got {value}")
    return int(value)


def serve(
    source,
    rate: float = 1.0,
    loop: bool = False,
    host: str = "127.0.0.1",
    dvl_port: int | None = 16171,
    ping_port: int | None = 9090,
    mavlink: str | None = DEFAULT_ADDRESS,
    faults: Faults | None = None,
    seed: int = 0,
    *,
    duration: float | None = None,
    epoch: float | None = None,
    distance_sensor: bool = False,
    wait_for_clients: float | None = None,
    topics=None,
    autopilot: bool = False,
    autopilot_params=None,
    autopilot_origin=None,
    autopilot_covariance: str = "cbrt",
) -> ServeSession:
    """A :class:`ServeSession` of ``source`` (see :func:`load_source`), not started.

    ``dvl_port``/``ping_port`` None (or ``mavlink`` None) leaves that sensor out; a sensor whose
    streams the log lacks is left out too. ``seed`` seeds the faults (numpy SeedSequence);
    ``epoch``: the sensor clock's epoch (default: wall start - t0, module
    :mod:`undertow.sim.robot.player`); ``distance_sensor``: also send the sonar as MAVLink
    DISTANCE_SENSOR; ``wait_for_clients``: wait up to that many seconds for an A50 client and a
    Ping request before playing. ``autopilot``: the virtual autopilot on the MAVLink link, with
    ``autopilot_params`` (a mapping or an ArduPilot parameter file), ``autopilot_origin``
    (LAT,LON[,ALT] or a tuple) and ``autopilot_covariance`` (``cbrt`` or ``sqrt``; see
    :mod:`undertow.sim.robot.autopilot`)."""
    if not isinstance(host, str) or not host.strip():
        raise ConfigError(f"--host: expected an address to bind, got {host!r}")
    if not (isinstance(rate, int | float) and math.isfinite(rate) and rate > 0):
        raise ConfigError(f"--rate: expected a positive number, got {rate}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ConfigError(f"--seed: expected a non-negative integer, got {seed}")
    dvl_port, ping_port = _port(dvl_port, "--dvl-port"), _port(ping_port, "--ping-port")
    faults = faults or Faults()
    log = load_source(source, duration, topics)
    manifest = Manifest()
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(3)]
    ports = (dvl_port, ping_port, mavlink)
    args = (log, manifest, faults, rngs, host, ports, distance_sensor, autopilot)
    a50, ping, sender = _servers(*args)
    ap = (autopilot_params, autopilot_origin, autopilot_covariance)
    link = _autopilot(sender, *ap) if autopilot else None
    sinks = [s for s in (ping, sender) if s is not None]
    if a50 is not None:
        sinks.insert(0, A50Reports(a50, log, manifest, faults, rngs[0]))
    if not sinks:
        raise ConfigError(
            f"{log.source or 'log'}: nothing to serve: no DVL, dead reckoning, "
            "sonar, IMU or pressure stream for the sensors asked"
        )
    player = Player(
        log,
        sinks,
        rate=rate,
        loop=loop,
        faults=faults,
        epoch=epoch,
        on_drop=a50.set_down if a50 else None,
        wait_for_clients=wait_for_clients,
    )
    return ServeSession(
        log, player, manifest, faults, float(rate), bool(loop), a50, ping, sender, link
    )


def _servers(log, manifest, faults, rngs, host, ports, distance_sensor, autopilot):
    """The A50, Ping1D and MAVLink servers of ``log`` (None for one not asked or without
    streams; the MAVLink sender also when the autopilot needs the link)."""
    dvl_port, ping_port, mavlink = ports
    has = {n for n, s in log.streams().items() if len(s)}
    a50 = (
        A50Server(host, dvl_port, served_config(log))
        if dvl_port is not None and has & {"dvl", "dead_reckoning"}
        else None
    )
    ping = (
        Ping1DServer(log, manifest, faults, rngs[1], host, ping_port)
        if ping_port is not None and "sonar" in has
        else None
    )
    wanted = has & {"imu", "pressure"} | ({"sonar"} if distance_sensor else set())
    sender = (
        MavlinkSender(log, manifest, faults, rngs[2], mavlink, distance_sensor)
        if mavlink and (wanted or autopilot)
        else None
    )
    return a50, ping, sender


def parse_origin(text) -> tuple[float, ...] | None:
    """``LAT,LON[,ALT]`` (deg, deg, m) as a tuple; a tuple passes; None stays None."""
    if text is None or isinstance(text, tuple | list):
        return None if text is None else tuple(float(v) for v in text)
    parts = str(text).split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--autopilot-origin: expected LAT,LON[,ALT] in degrees, got {text!r}")
    return values


def _autopilot(sender: MavlinkSender | None, params, origin, covariance: str) -> AutopilotLink:
    """The virtual autopilot on ``sender``'s link (its attitude and baro depth from the log)."""
    if sender is None:
        raise ConfigError("--autopilot: the virtual autopilot needs the MAVLink link (--mavlink)")
    if params is not None and not isinstance(params, dict):
        params = load_param_file(params)
    ap = VirtualAutopilot(
        params,
        parse_origin(origin),
        covariance=covariance,
        attitude=log_attitude(sender),
        depth=log_depth(sender),
    )
    return AutopilotLink(ap, sender)
