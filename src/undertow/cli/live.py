"""`undertow live`: the online filter, map and sea state on a robot's live sensors."""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Annotated

import typer

from ._app import ConfigOption, OverwriteOption, app, err, user_errors

# the options of `--autopilot` (docs/live.md, "Sending to the autopilot")
AutopilotFlag = Annotated[
    bool, typer.Option("--autopilot", help="Send the estimate to the autopilot (--mavlink).")
]
AutopilotMode = Annotated[
    str | None, typer.Option(help="odometry (ODOMETRY, default), vision-position, velocity-delta.")
]
AutopilotRate = Annotated[
    float | None, typer.Option(help="Messages per second to the autopilot (10, >= 5).")
]
OriginOption = Annotated[
    str | None, typer.Option(help="EKF origin LAT,LON[,ALT], sent once if none is set.")
]
SetParamsFlag = Annotated[
    bool, typer.Option("--set-params", help="Set the autopilot parameters it needs.")
]


@app.command("live")
@user_errors
def live_command(
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder (recording, results).")],
    dvl: Annotated[
        str | None, typer.Option(help="Water Linked A50: tcp://HOST[:PORT] (port 16171).")
    ] = None,
    sonar: Annotated[
        str | None, typer.Option(help="Ping1D: udp://HOST:PORT (BlueOS: 9090) or a serial device.")
    ] = None,
    mavlink: Annotated[
        str | None, typer.Option(help="Autopilot, a pymavlink address: udpin:0.0.0.0:14550.")
    ] = None,
    variant: Annotated[str | None, typer.Option(help="Filter variant (proposed).")] = None,
    wave: Annotated[
        str | None, typer.Option(help="auto (estimated online) or a condition name; default calm.")
    ] = None,
    calibration: Annotated[
        Path | None, typer.Option(help="Calibration YAML from `undertow calibrate`.")
    ] = None,
    no_map: Annotated[bool, typer.Option("--no-map", help="Do not map online.")] = False,
    view: Annotated[
        bool, typer.Option("--view", help="Serve the Foxglove live view (WebSocket).")
    ] = False,
    view_port: Annotated[int | None, typer.Option(help="Live view port (8765).")] = None,
    time_scale: Annotated[
        float | None,
        typer.Option(
            help="Sensor seconds per wall second: R when the sensors are `serve --rate R`."
        ),
    ] = None,
    reorder: Annotated[
        float | None, typer.Option(help="Reorder buffer, sensor seconds (0.25).")
    ] = None,
    duration: Annotated[float | None, typer.Option(help="Stop after this many seconds.")] = None,
    idle_stop: Annotated[
        float | None, typer.Option(help="Stop once no data came for this many seconds.")
    ] = None,
    autopilot: AutopilotFlag = False,
    autopilot_mode: AutopilotMode = None,
    autopilot_rate: AutopilotRate = None,
    origin: OriginOption = None,
    set_params: SetParamsFlag = False,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No status line.")] = False,
) -> None:
    """Run the filter, the map and the sea-state estimate live on the sensors' own protocols;
    record every input and estimate (ROS 2 mcap), and at the end (Ctrl-C, SIGTERM,
    --duration, --idle-stop) write localization/ and map/ next to the recording.

    Example: `undertow live --dvl tcp://192.168.194.95 --sonar udp://192.168.2.2:9090
    --mavlink udpin:0.0.0.0:14550 --wave auto --out dive1`; add `--autopilot` to let the
    vehicle navigate on the estimate (docs/live.md).
    """
    from ..commands.live import live_settings
    from ..live.pipeline import LiveSession

    settings = live_settings(
        config, variant=variant, dvl=dvl, sonar=sonar, mavlink=mavlink, wave=wave,
        time_scale=time_scale, view_port=view_port, duration_s=duration, idle_stop_s=idle_stop,
        reorder_s=reorder, view=True if view else None, map=False if no_map else None,
        autopilot=True if autopilot else None, autopilot_mode=autopilot_mode,
        autopilot_rate_hz=autopilot_rate, autopilot_origin=origin,
        autopilot_set_params=True if set_params else None,
    )  # fmt: skip
    live_view = _open_view(settings) if settings.live.view else None
    session = LiveSession(settings, out_dir, calibration=calibration, overwrite=overwrite,
                          view=live_view)  # fmt: skip
    if not quiet and err.is_terminal:
        session.status_callback = _status_printer()
    if not quiet:
        session.on_notice = lambda line: err.print(f"\n[yellow]note:[/] {line}", highlight=False)
    _run(session, quiet)


def _open_view(settings):
    from ..live.view import LiveView

    live = settings.live
    view = LiveView(host=live.view_host, port=live.view_port, autopilot=live.autopilot)
    err.print(f"live view: ws://{settings.live.view_host}:{view.port} (Foxglove: open connection)")
    return view


def _run(session, quiet: bool) -> None:
    """Run until stopped; the first Ctrl-C stops cleanly (results written), a second aborts
    (the recording closed, nothing half-written)."""

    def first_interrupt(signum, frame):
        session.request_stop()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        err.print("\nstopping: writing the results (Ctrl-C again to abort)")

    previous = signal.signal(signal.SIGINT, first_interrupt)
    session.start()
    if not session.wait_connected(2.0):
        err.print("[yellow]note:[/] a link has not connected yet; it keeps trying", highlight=False)
    try:
        result = session.run()
    except BaseException:
        session.abort()
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
    if not quiet:
        for note in result.warnings:
            err.print(f"[yellow]note:[/] {note}", highlight=False, soft_wrap=True)
        s = result.summary
        lat = s["latency"]
        err.print(f"records {s['records']}, late {s['late']}, states {s['states']}, "
                  f"pings mapped {s['pings_mapped']}"
                  + (f", DVL-to-pose latency median {lat['median_ms']:.2f} ms" if lat["n"] else ""),
                  highlight=False, soft_wrap=True)  # fmt: skip
        err.print(f"wrote {result.out_dir}", highlight=False)


def _status_printer():
    def show(status: dict) -> None:
        links = status["links"]
        rates = " ".join(f"{k}:{v}" for k, v in sorted(status["records"].items()))
        dropped = sum(c["malformed"] + c["stale"] + c["overflow"] for c in links.values())
        line = (f"t={status['clock']:.1f} {rates} dropped={dropped} late={status['late']} "
                f"filter={status['filter']} states={status['states']} "
                f"pings={status['pings_mapped']}")  # fmt: skip
        err.file.write("\r" + line[: max(err.width - 1, 20)].ljust(max(err.width - 1, 20)))
        err.file.flush()

    return show
