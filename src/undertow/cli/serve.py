"""The virtual robot command: serve (parse, call :func:`undertow.commands.serve.serve`,
print)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import Terminated
from ._app import app, console, err, print_json, user_errors


def _print_start(session, quiet: bool) -> None:
    if quiet:
        return
    e, player = session.endpoints, session.player
    wall = player.span / session.rate
    how = "looping" if session.loop else f"about {wall:.1f} s"
    err.print(
        f"serving {session.log.source or 'log'}: {player.span:.1f} s of log at "
        f"{session.rate:g}x real time ({how})",
        highlight=False,
        soft_wrap=True,
    )
    rows = (("A50 DVL (TCP JSON)", e.dvl), ("Ping1D (UDP)", e.sonar), ("MAVLink", e.mavlink))
    for name, value in rows:
        if value:
            err.print(f"  {name:<20} {value}", highlight=False, soft_wrap=True)
    if session.autopilot is not None:
        ap = session.autopilot.autopilot
        origin = "origin preset" if ap.origin_preset else "no origin"
        err.print(
            f"  {'virtual autopilot':<20} EKF3 external-navigation rules on the MAVLink link "
            f"({ap.covariance} covariance, {origin})",
            highlight=False,
            soft_wrap=True,
        )
    if session.faults.any:
        err.print(f"  faults: {session.faults.to_dict()}", highlight=False, soft_wrap=True)
    err.print("  undertow live " + " ".join(e.live_options()), highlight=False, soft_wrap=True)


def _print_summary(summary: dict, as_json: bool) -> None:
    if as_json:
        print_json(summary)
        return
    from rich.table import Table

    table = Table(
        title=f"served: {summary['played_s']:.1f} s of log ({summary['span_s']:.1f} s a lap)"
    )
    table.add_column("message")
    table.add_column("count", justify="right")
    for name, count in summary["messages"].items():
        table.add_row(name, str(count))
    for name, count in summary["faults"].items():
        table.add_row(f"fault: {name}", str(count))
    console.print(table)
    err.print(
        f"A50 connections {summary['a50_connections']}, commands "
        f"{summary['a50_commands'] or 'none'}; Ping requests {summary['ping_requests']}",
        highlight=False,
        soft_wrap=True,
    )
    ap = summary.get("autopilot")
    if ap:
        counts = ", ".join(f"{k} {v}" for k, v in ap["counts"].items()) or "nothing received"
        err.print(
            f"virtual autopilot: aiding {ap['aiding']}, EKF flags {ap['flags']}, origin "
            f"{ap['origin'] or 'not set'}; {counts}",
            highlight=False,
            soft_wrap=True,
        )


def _run(session, quiet: bool, manifest: Path | None) -> dict:
    """Play until the end (or Ctrl-C / SIGTERM), stop, write the manifest; the summary."""
    session.open()
    try:
        _print_start(session, quiet)
        session.start()
        while not session.wait(0.2):
            pass
    except (KeyboardInterrupt, Terminated):
        if not quiet:
            err.print("stopped", highlight=False)
    finally:
        summary = session.stop()
        if manifest is not None:
            session.manifest.write(manifest)
    return summary


AutopilotFlag = Annotated[
    bool,
    typer.Option(
        "--autopilot",
        help="Run a virtual ArduSub autopilot on the MAVLink link that consumes external "
        "navigation (ODOMETRY, VISION_POSITION_*) as EKF3 does and reports back.",
    ),
]
AutopilotParams = Annotated[
    Path | None,
    typer.Option(help="ArduPilot parameter file (NAME VALUE lines) preset on the autopilot."),
]
AutopilotOrigin = Annotated[
    str | None, typer.Option(help="LAT,LON[,ALT] - an EKF origin already set on the autopilot.")
]
AutopilotCovariance = Annotated[
    str,
    typer.Option(
        help="How the firmware reduces a pose covariance: cbrt (ArduSub 4.x) or sqrt "
        "(ArduPilot master since PR 32084)."
    ),
]


@app.command("serve")
@user_errors
def serve_command(
    source: Annotated[
        str,
        typer.Argument(
            metavar="LOG_OR_SCENARIO",
            help="A log (bag, A50 JSON log, .tlog) or a scenario (built-in name or YAML file, "
            "simulated first).",
        ),
    ],
    rate: Annotated[float, typer.Option(help="Playback speed, x real time.")] = 1.0,
    loop: Annotated[bool, typer.Option("--loop", help="Start again at the end.")] = False,
    host: Annotated[
        str, typer.Option(help="Address to bind; the default serves this machine only.")
    ] = "127.0.0.1",
    dvl_port: Annotated[int, typer.Option(help="A50 TCP port (0: any free).")] = 16171,
    ping_port: Annotated[int, typer.Option(help="Ping1D UDP port (0: any free).")] = 9090,
    mavlink: Annotated[
        str, typer.Option(help="pymavlink address to send MAVLink to ('off': none).")
    ] = "udpout:127.0.0.1:14550",
    drop_dvl: Annotated[
        list[str] | None,
        typer.Option(help="T:N - close the A50 connection at T s for N s (repeatable)."),
    ] = None,
    corrupt: Annotated[
        float,
        typer.Option(help="Fraction of A50 lines, Ping replies and MAVLink packets corrupted."),
    ] = 0.0,
    duplicate: Annotated[float, typer.Option(help="Fraction of A50 reports sent twice.")] = 0.0,
    reorder: Annotated[
        float, typer.Option(help="Fraction of A50 reports sent after the next one.")
    ] = 0.0,
    clock_jump: Annotated[
        list[str] | None,
        typer.Option(
            help="STREAM:T:S - jump a sensor clock (dvl, dead_reckoning, a50, imu, pressure, "
            "mavlink) by S s at T s (repeatable)."
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the faults.")] = 0,
    duration: Annotated[
        float | None, typer.Option(help="Serve only the first S s of the log.")
    ] = None,
    distance_sensor: Annotated[
        bool,
        typer.Option("--distance-sensor", help="Also send the sonar as MAVLink DISTANCE_SENSOR."),
    ] = False,
    wait_clients: Annotated[
        float | None,
        typer.Option(help="Wait up to S s for the A50 and Ping clients before playing."),
    ] = None,
    manifest: Annotated[
        Path | None, typer.Option(help="Write every message served here (JSON lines).")
    ] = None,
    autopilot: AutopilotFlag = False,
    autopilot_params: AutopilotParams = None,
    autopilot_origin: AutopilotOrigin = None,
    autopilot_covariance: AutopilotCovariance = "cbrt",
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No endpoints on stderr.")] = False,
) -> None:
    """Play a log or a simulated scenario as live sensors on this machine: a Water Linked A50
    (TCP JSON), a Ping1D (UDP, Ping protocol) and an ArduSub autopilot (MAVLink), with optional
    faults; prints the endpoints, and what was served when the log ends or on Ctrl-C.

    Example: `undertow serve calm --rate 10 --drop-dvl 5:2 --corrupt 0.01`; with a virtual
    autopilot: `undertow serve calm --autopilot --autopilot-params ext_nav.parm`
    """
    from ..commands.serve import serve
    from ..sim.robot import Faults

    faults = Faults.from_options(drop_dvl or (), corrupt, duplicate, reorder, clock_jump or ())
    mavlink_to = None if mavlink.lower() in ("off", "none", "") else mavlink
    options = dict(duration=duration, distance_sensor=distance_sensor)
    options.update(wait_for_clients=wait_clients, autopilot=autopilot)
    options.update(autopilot_params=autopilot_params, autopilot_origin=autopilot_origin)
    session = serve(
        source, rate, loop, host, dvl_port, ping_port, mavlink_to, faults, seed, **options,
        autopilot_covariance=autopilot_covariance,
    )  # fmt: skip
    _print_summary(_run(session, quiet, manifest), as_json)
