"""The robot's description: its DVL's beam geometry (presets for common heads, beam unit
vectors) and where each sensor sits on the body (:class:`SensorMount`, :class:`Mounting`, with the
BlueROV2 defaults of the paper's lab).

Frames as in :mod:`undertow.log`: body forward-right-down, DVL frame x forward, y right, z down,
origin where the beam axes meet.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

#: Azimuths (deg, about +z from +x toward +y) of the A50's beams for protocol ids 0..3.
A50_AZIMUTHS_DEG = (135.0, -135.0, -45.0, 45.0)


def a50_beam_units(tilt_deg: float = 22.5) -> np.ndarray:
    """Unit vectors of the A50's four beams in the DVL frame, rows for protocol ids 0..3.

    b_i = (sin(tilt) cos(az_i), sin(tilt) sin(az_i), cos(tilt)), az = +135, -135, -45, +45 deg
    about +z from +x (Water Linked DVL documentation, "Axes": x forward, y right, z down; protocol
    ids 0..3 are transducers 1..4): horizontal part 0.383, vertical 0.924 for the 22.5 deg tilt.
    """
    return dvl_beam_units(tilt_deg, A50_AZIMUTHS_DEG)


def dvl_beam_units(tilt_deg: float, azimuths_deg) -> np.ndarray:
    """Unit vectors (B, 3) of a Janus DVL's beams in the DVL frame (x forward, y right, z down):

        b_i = (sin(tilt) cos(az_i), sin(tilt) sin(az_i), cos(tilt)),

    tilt the angle of every beam from the +z axis, az_i its azimuth about +z from +x toward +y.
    """
    tilt = np.deg2rad(tilt_deg)
    az = np.deg2rad(np.asarray(azimuths_deg, dtype=np.float64))
    n = az.size
    return np.stack(
        [np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.full(n, np.cos(tilt))], axis=1
    )


A50_UNITS = a50_beam_units()  # the default geometry's beams, made once (read-only)
A50_UNITS.setflags(write=False)


@dataclass(frozen=True)
class DvlGeometry:
    """A DVL's beam geometry: ``tilt_deg`` of every beam from the DVL's +z axis, one azimuth
    per beam (deg about +z from +x toward +y, in the order of the sensor's beam ids) and the
    one-way beam width (deg, full -3 dB angle; None if not given). The beam
    vectors are :func:`dvl_beam_units` (tilt, azimuths)."""

    name: str
    tilt_deg: float
    azimuths_deg: tuple[float, ...]
    beam_width_deg: float | None = None

    def __post_init__(self) -> None:
        from .errors import ConfigError

        az = tuple(float(a) for a in self.azimuths_deg)
        object.__setattr__(self, "azimuths_deg", az)
        if not 0.0 < float(self.tilt_deg) < 90.0 or not math.isfinite(float(self.tilt_deg)):
            raise ConfigError(f"dvl geometry {self.name}: tilt_deg {self.tilt_deg} not in (0, 90)")
        if len(az) < 3 or not all(math.isfinite(a) for a in az):
            raise ConfigError(
                f"dvl geometry {self.name}: need at least 3 finite beam azimuths, got {list(az)}"
            )

    @property
    def beams(self) -> int:
        return len(self.azimuths_deg)

    def units(self) -> np.ndarray:
        """The beam unit vectors (B, 3), rows in beam-id order."""
        return dvl_beam_units(self.tilt_deg, self.azimuths_deg)

    def to_dict(self) -> dict:
        out = {
            "name": self.name,
            "tilt_deg": float(self.tilt_deg),
            "azimuths_deg": [float(a) for a in self.azimuths_deg],
        }
        if self.beam_width_deg is not None:
            out["beam_width_deg"] = float(self.beam_width_deg)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> DvlGeometry:
        """From :meth:`to_dict`'s fields; a missing or malformed one raises ConfigError."""
        from .errors import ConfigError

        try:
            width = data.get("beam_width_deg")
            return cls(
                name=str(data.get("name", "custom")),
                tilt_deg=float(data["tilt_deg"]),
                azimuths_deg=tuple(float(a) for a in data["azimuths_deg"]),
                beam_width_deg=None if width is None else float(width),
            )
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            # (OverflowError: an integer too large for a float, as a YAML file may hold)
            raise ConfigError(f"dvl_geometry: malformed ({type(exc).__name__}: {exc})") from None


#: DVL presets (manufacturer datasheets; all four-beam Janus heads):
#:
#: - ``a50``: Water Linked DVL A50 datasheet and documentation ("Axes"): 4 beams at 22.5 deg
#:   from the vertical, transducers 1..4 at azimuths +135, -135, -45, +45 deg from forward.
#: - ``dvl1000``: Nortek DVL1000 datasheet: 4 beams at 25 deg; Nortek's X-configuration head
#:   puts the beams 45 deg off the instrument's x axis (azimuths +45, -45, -135, +135 deg here,
#:   beams 1..4).
#: - ``pathfinder``: Teledyne RDI Pathfinder DVL datasheet: 4 beams at 30 deg, Janus. Beam
#:   numbering from the Pathfinder DVL Guide (P/N 95B-6116-00, 2018) mounted beam 3 forward:
#:   its instrument Y axis points to beam 3 and X to beam 2 ("if Beam 2 is going forward, then
#:   X velocity is positive", PD4-PD13 formats), Z up for a down-facing unit (right-handed), so
#:   beam 2 is to starboard (+90 deg), 1 to port (-90), 3 forward (0), 4 aft (180); the Guide's
#:   roll sign agrees (Tilt 2 positive when beam 2 is higher than beam 1 is negative facing
#:   down, i.e. starboard up is negative roll).
#:
#: The DVL1000's numbering comes from a figure of Nortek's manual that could not be read here:
#: check it against your unit before relying on beam ids (the velocity does not depend on it).
#: Beam widths are left None (not modelled): the ray caster casts one ray per beam axis.
DVL_PRESETS: dict[str, DvlGeometry] = {
    "a50": DvlGeometry("a50", 22.5, A50_AZIMUTHS_DEG),
    "dvl1000": DvlGeometry("dvl1000", 25.0, (45.0, -45.0, -135.0, 135.0)),
    "pathfinder": DvlGeometry("pathfinder", 30.0, (-90.0, 90.0, 0.0, 180.0)),
}


def dvl_preset(name: str) -> DvlGeometry:
    """The preset geometry ``name`` (:data:`DVL_PRESETS`); unknown names raise ConfigError."""
    from .errors import ConfigError

    try:
        return DVL_PRESETS[name]
    except KeyError:
        raise ConfigError(f"dvl model {name!r}: unknown (use {', '.join(DVL_PRESETS)})") from None


@dataclass(frozen=True)
class SensorMount:
    """Where a sensor sits on the body: lever arm (m, body FRD) and rotation roll, pitch, yaw
    (rad) of the sensor frame relative to the body frame."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation_matrix(self) -> np.ndarray:
        """R_sensor^body = Rz(yaw) Ry(pitch) Rx(roll)."""
        from .rotations import rpy_to_matrix

        return rpy_to_matrix(np.asarray(self.rotation, dtype=float))


def _bluerov2_dvl() -> SensorMount:
    return SensorMount((0.164, 0.004, 0.284), (0.0, 0.0, 0.05))


def _bluerov2_sonar() -> SensorMount:
    return SensorMount((0.164, 0.106, 0.306), (0.0, 0.0, 0.0))


def _bluerov2_multibeam() -> SensorMount:
    return SensorMount((0.25, 0.0, 0.3), (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class Mounting:
    """Sensor mounting on the body (defaults: a public BlueROV2 URDF of the paper's lab: DVL at
    (0.164, 0.004, 0.284) m turned 0.05 rad about z, Ping sonar at (0.164, 0.106, 0.306) m).

    The sonar frame's +z is its acoustic axis (looking down when the rotation is zero). The
    multibeam (a head under the bow at (0.25, 0, 0.3) m, assumed) has x along track, y
    starboard, z down: its swath lies in the body's y-z plane when the rotation is zero.
    """

    imu: SensorMount = field(default_factory=SensorMount)
    dvl: SensorMount = field(default_factory=_bluerov2_dvl)
    sonar: SensorMount = field(default_factory=_bluerov2_sonar)
    barometer: SensorMount = field(default_factory=SensorMount)
    multibeam: SensorMount = field(default_factory=_bluerov2_multibeam)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Mounting:
        return cls().updated(data)

    def updated(self, changes: dict) -> Mounting:
        """A copy with the given sensors' fields replaced, e.g. ``{"imu": {"rotation": [pi, 0,
        0]}}``; fields not named keep their value. Unknown sensors or fields raise ConfigError."""
        from .errors import ConfigError

        mounts = dataclasses.asdict(self)
        for sensor, fields in (changes or {}).items():
            if sensor not in mounts or not isinstance(fields, dict):
                raise ConfigError(f"mounting.{sensor}: unknown sensor (use {', '.join(mounts)})")
            for name, value in fields.items():
                try:
                    vector = tuple(float(v) for v in value)
                except (TypeError, ValueError, OverflowError):
                    vector = ()
                if name not in ("translation", "rotation") or len(vector) != 3:
                    raise ConfigError(
                        f"mounting.{sensor}.{name}: expected translation or rotation, 3 numbers"
                    )
                if not all(math.isfinite(v) for v in vector):
                    raise ConfigError(
                        f"mounting.{sensor}.{name}: non-finite values (3 finite numbers expected)"
                    )
                mounts[sensor][name] = vector
        return Mounting(**{k: SensorMount(**v) for k, v in mounts.items()})
