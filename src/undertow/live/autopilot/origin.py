"""The EKF origin: read what the vehicle has, adopt it, or set it once.

ArduPilot accepts SET_GPS_GLOBAL_ORIGIN only while it has no origin (``set_ekf_origin`` answers
MAV_RESULT_FAILED once one is set, and a latitude/longitude out of range is dropped silently;
libraries/GCS_MAVLink/GCS_Common.cpp), and announces the new origin with GPS_GLOBAL_ORIGIN;
it answers MAV_CMD_REQUEST_MESSAGE (512) for GPS_GLOBAL_ORIGIN (49) with the message only when it
has an origin. So, from the moment the autopilot is found:

1. ask for GPS_GLOBAL_ORIGIN ``asks`` times, ``every_s`` apart;
2. an origin that arrives (then, or any time later) is **adopted**: stated in one line, never
   fought (``--origin`` is then not sent);
3. none after the asks: with ``--origin LAT,LON[,ALT]``, send SET_GPS_GLOBAL_ORIGIN (latitude
   and longitude in degE7, altitude in mm) and ask again to see it confirmed; unconfirmed, send
   it again, at most ``sets`` times in all: ArduPilot refuses an origin silently before its EKF
   runs (``setOriginLLH`` of an EKF core not yet initialised, a few seconds after boot, e.g.
   right after the reboot that parameters need), and a repeat cannot fight an origin set
   meanwhile (it takes one only while it has none); without, say that the vehicle has no origin.

An autopilot reboot forgets its origin: :meth:`OriginKeeper.rebooted` starts again.
"""

from __future__ import annotations

import math

#: GPS_GLOBAL_ORIGIN's message id and MAV_CMD_REQUEST_MESSAGE (common.xml)
GPS_GLOBAL_ORIGIN_ID = 49
MAV_CMD_REQUEST_MESSAGE = 512


def describe(lat_deg: float, lon_deg: float, alt_m: float) -> str:
    return f"{lat_deg:.7f}, {lon_deg:.7f}, {alt_m:.1f} m"


class OriginKeeper:
    """The steps of the module docstring; :meth:`step` returns the actions due, :meth:`seen`
    takes a GPS_GLOBAL_ORIGIN; both return the one-line notes to tell."""

    def __init__(self, wanted=None, *, asks: int = 3, every_s: float = 1.0,
                 sets: int = 3) -> None:  # fmt: skip
        self.wanted = None if wanted is None else tuple(float(v) for v in wanted)
        self.asks = int(asks)
        self.sets = int(sets)
        self.every_s = float(every_s)
        self.rebooted()

    def rebooted(self) -> None:
        self.state = "unknown"  # unknown, asking, sent, adopted, set, none
        self.origin: tuple[float, float, float] | None = None
        self._asked = 0
        self._next = None
        self._sent = 0  # SET_GPS_GLOBAL_ORIGIN sent this boot

    def step(self, now: float) -> tuple[list[tuple], list[str]]:
        """(actions, notes): actions ("request",) or ("set", lat_e7, lon_e7, alt_mm)."""
        if self.state in ("adopted", "set", "none") or (
            self._next is not None and now < self._next
        ):
            return [], []
        self._next = now + self.every_s
        if self._asked < self.asks:
            self._asked += 1
            self.state = "asking" if self.state == "unknown" else self.state
            return [("request",)], []
        if self.state == "sent" and self._sent >= self.sets:
            self.state = "none"
            return [], ["no GPS_GLOBAL_ORIGIN came back after SET_GPS_GLOBAL_ORIGIN: the vehicle "
                        "refused or did not hear it (an origin is set once per boot)"]  # fmt: skip
        if self.wanted is not None and self._sent < self.sets:
            lat, lon, *alt = self.wanted
            again = self._sent > 0
            self._sent, self.state, self._asked = self._sent + 1, "sent", 0
            action = ("set", int(round(lat * 1e7)), int(round(lon * 1e7)),
                      int(round((alt[0] if alt else 0.0) * 1e3)))  # fmt: skip
            where = describe(lat, lon, action[3] / 1e3)
            if again:  # (said once: the EKF may not have run yet)
                return [action], [] if self._sent > 2 else [
                    f"EKF origin: not confirmed; sending {where} again (an EKF that has not "
                    "started refuses it)"]  # fmt: skip
            return [action], [f"EKF origin: none on the vehicle; setting {where}"]
        self.state = "none"
        return [], ["EKF origin: the vehicle has none; ArduSub's position modes need one "
                    "(--origin LAT,LON[,ALT] sets it)"]  # fmt: skip

    def seen(self, latitude, longitude, altitude) -> list[str]:
        """A GPS_GLOBAL_ORIGIN (degE7, degE7, mm): adopted, or the one undertow set confirmed."""
        try:
            lat, lon, alt = float(latitude) * 1e-7, float(longitude) * 1e-7, float(altitude) * 1e-3
        except (TypeError, ValueError):
            return []
        if not (math.isfinite(lat + lon + alt) and abs(lat) <= 90 and abs(lon) <= 180):
            return []
        new = (lat, lon, alt)
        if self.origin is not None and all(
            abs(a - b) < 1e-6 for a, b in zip(self.origin, new, strict=True)
        ):
            return []
        self.origin = new
        if self.state == "sent" and self.wanted is not None and _near(new, self.wanted):
            self.state = "set"
            return [f"EKF origin set: {describe(*new)}"]
        self.state = "adopted"
        ignored = " (--origin not sent)" if self.wanted is not None and not self._sent else ""
        return [f"EKF origin already on the vehicle: {describe(*new)}; adopted{ignored}"]


def _near(got, wanted) -> bool:
    return abs(got[0] - wanted[0]) < 1e-6 and abs(got[1] - wanted[1]) < 1e-6
