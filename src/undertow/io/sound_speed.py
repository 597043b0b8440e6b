"""The sound speed the acoustic sensors measured in: ``log: {sound_speed_m_s: C}`` or
``log: {water_temperature_c: T}``.

A DVL and a single-beam echo sounder (the Ping) turn times into metres with the sound speed they
are set to, c_set, not the water's, c:

- a range is c_set t / 2 of the echo's two-way travel time t;
- a DVL beam's radial velocity is c_set f_D / (2 f_0) of its Doppler shift f_D (carrier f_0),
  so a DVL with fixed beam angles (piston transducers, as the A50's) scales its velocity alike;

so every range and velocity they report is c_set / c times the true one, and the correction is

    k = c / c_set,   r = k r_reported,   v = k v_reported,   Cov(v) = k^2 Cov(v_reported)

(the DVL's altitude, beam ranges, beam velocities and figure of merit with its k, the sonar's
ranges with its own). A 1500 m/s setting in fresh water at 15-20 C (1466-1482 m/s) makes both
1.2-2.3 % too long: a floor 2.5 m below the sensor mapped 3-6 cm too deep, a track 1.2-2.3 m
too long per 100 m run.

The set values are ``dvl_sound_speed_m_s`` and ``sonar_sound_speed_m_s``. The DVL's, when
not set, is the one its messages said (``marine_acoustic_msgs/Dvl.sound_speed``, WHOI's
``speed_sound``; the log's metadata ``dvl_sound_speed_m_s``), else 1500 m/s, the Water Linked
A50's fixed value (its documentation: "The DVL-A50 uses a constant speed of sound equal to
1500 m/s", configurable on later firmware through ``set_config``'s ``speed_of_sound``; its
driver's messages do not carry it). The sonar's is 1500 m/s unless set, the Ping1D's default
(ping-protocol ``set_speed_of_sound``, 1,500,000 mm/s; its ``distance`` message does not
carry it).

The water's sound speed is ``sound_speed_m_s``, or from ``water_temperature_c`` by Coppens'
equation (A. B. Coppens, "Simple equations for the speed of sound in Neptunian waters", JASA
69(3), 1981; 0-35 C, salinity 0-45, 0-4000 m) for the settings' ``water`` (fresh: salinity 0,
salt: 35) at the surface (16 m/s per km deeper: 0.05 m/s at 3 m):

    c(0, S, t) = 1449.05 + 45.7 t - 5.21 t^2 + 0.23 t^3 + (1.333 - 0.126 t + 0.009 t^2)(S - 35),

t = T / 10. Neither given (the default): the log is left as recorded, and its metadata says so
(``sound_speed``, in every output's ``config.yaml``). The DVL's dead-reckoned positions are left
as recorded (their origin is the DVL's last reset, which the log need not hold; the filter
reads only their orientation), and so are a multibeam's detections (a multibeam head forms its
beams with the sound speed measured at its face).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np

from ..log import Log

#: the sound speed the A50 (standard edition) and the Ping1D convert with unless set otherwise
DEFAULT_SET_SOUND_SPEED = 1500.0
#: the salinity (g/kg) Coppens' equation takes for the settings' ``water``
SALINITY = {"fresh": 0.0, "salt": 35.0}


def coppens_sound_speed(temperature_c: float, salinity: float) -> float:
    """c(0, S, t) of Coppens (1981) at the surface (module doc), m/s."""
    t = float(temperature_c) / 10.0
    s = float(salinity) - 35.0
    return (1449.05 + 45.7 * t - 5.21 * t * t + 0.23 * t**3
            + (1.333 - 0.126 * t + 0.009 * t * t) * s)  # fmt: skip


def water_sound_speed(options) -> tuple[float | None, str]:
    """(c m/s or None, where it comes from) of the ``log:`` settings ``options``."""
    if options.sound_speed_m_s is not None:
        return float(options.sound_speed_m_s), "settings (sound_speed_m_s)"
    if options.water_temperature_c is not None:
        c = coppens_sound_speed(options.water_temperature_c, SALINITY[options.water])
        return c, f"{options.water} water at {options.water_temperature_c:g} C (Coppens 1981)"
    return None, "not corrected"


def dvl_set_speed(options, metadata: dict) -> tuple[float, str]:
    """(c_set of the DVL in m/s, where it comes from): the settings', else the log's (its
    messages'), else the A50's fixed 1500 m/s (module doc)."""
    if options.dvl_sound_speed_m_s is not None:
        return float(options.dvl_sound_speed_m_s), "settings"
    said = metadata.get("dvl_sound_speed_m_s") if isinstance(metadata, dict) else None
    if isinstance(said, (int, float)) and math.isfinite(said) and said > 0:
        return float(said), "the log (its DVL messages' sound_speed)"
    return DEFAULT_SET_SOUND_SPEED, "the A50's fixed value, assumed"


def correct_sound_speed(log: Log, options, state: bool = True) -> Log:
    """``log`` with its DVL and sonar ranges and DVL velocities in the water's sound speed
    (module doc), recorded in ``metadata["sound_speed"]`` and, with ``state``, said in one line
    (a warning, also kept in ``metadata["warnings"]``); unchanged (and recorded so) without a
    water sound speed in ``options`` (:class:`~undertow.io.read_options.LogOptions`)."""
    c, source = water_sound_speed(options)
    dvl_set, dvl_from = dvl_set_speed(options, log.metadata)
    record = {"water_m_s": c, "source": source, "dvl_set_m_s": dvl_set, "dvl_set_from": dvl_from,
              "sonar_set_m_s": options.sonar_sound_speed_m_s}  # fmt: skip
    meta = dict(log.metadata)
    meta["sound_speed"] = record
    if c is None:
        return log.replace(metadata=meta)
    k_dvl, k_sonar = c / dvl_set, c / options.sonar_sound_speed_m_s
    record.update(dvl_factor=k_dvl, sonar_factor=k_sonar)
    changes = {}
    has_dvl = log.dvl is not None and len(log.dvl) > 0
    has_sonar = log.sonar is not None and len(log.sonar) > 0
    if has_dvl:
        changes["dvl"] = scaled_dvl(log.dvl, k_dvl)
    if has_sonar:
        changes["sonar"] = replace(log.sonar, range=np.asarray(log.sonar.range) * k_sonar)
    if changes and state:
        src = f"{log.source}: " if log.source else ""
        line = src + sound_speed_line(options, log.metadata, dvl=has_dvl, sonar=has_sonar)
        warnings.warn(line, stacklevel=3)
        meta["warnings"] = [*meta.get("warnings", []), line]
    return log.replace(metadata=meta, **changes)


def sound_speed_line(options, metadata=None, dvl: bool = True, sonar: bool = True) -> str:
    """The one line that states the correction of the ``log:`` settings ``options`` (a water
    sound speed given): the water's speed and where it comes from, and the factors of the DVL
    (its setting from :func:`dvl_set_speed` of ``metadata``) and of the sonar, as asked."""
    c, source = water_sound_speed(options)
    dvl_set, dvl_from = dvl_set_speed(options, metadata or {})
    sonar_set = options.sonar_sound_speed_m_s
    done = [f"DVL ranges and velocities x {c / dvl_set:.5f} (set to {dvl_set:g} m/s: "
            f"{dvl_from})"] if dvl else []  # fmt: skip
    if sonar:
        done.append(f"sonar ranges x {c / sonar_set:.5f} (set to {sonar_set:g} m/s)")
    return (f"sound speed {c:.1f} m/s from {source}: " + "; ".join(done)
            + "; set log: {dvl_sound_speed_m_s: C, sonar_sound_speed_m_s: C} to change what the"
            " sensors were set to")  # fmt: skip


def scaled_dvl(dvl, k: float):
    """The DVL stream with its ranges, velocities (and their covariance) times ``k``."""
    out = {"velocity": np.asarray(dvl.velocity) * k, "altitude": np.asarray(dvl.altitude) * k,
           "beam_range": np.asarray(dvl.beam_range) * k}  # fmt: skip
    for name, power in (("covariance", 2), ("fom", 1), ("beam_velocity", 1)):
        value = getattr(dvl, name, None)
        if value is not None:
            out[name] = np.asarray(value) * k**power
    return replace(dvl, **out)
