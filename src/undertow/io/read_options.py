"""How a log is read where the data cannot say it alone: the ``log:`` section of the settings.

Every field defaults to detection from the log itself (``auto``); what was detected is stated in
one line and recorded in the log's metadata (and so in every output's ``config.yaml``)::

    log:
      time: auto            # auto | header | record: the time base (undertow.io.clock)
      imu_units: auto       # auto | rad/s | deg/s: the gyro's unit (undertow.io.units)
      surface_pressure_pa: auto   # or a number (Pa): the pressure at the water surface
      water: fresh          # fresh | salt: water density 998 / 1025 kg/m^3
      depth_z: auto         # auto | down | up: which way a pose's z points (a depth topic)
      gps_origin: null      # [lat, lon, alt]: origin of the local frame of GPS fixes
      sound_speed_m_s: null # the water's sound speed (m/s): DVL and sonar ranges and DVL
      water_temperature_c: null   # velocities corrected to it (or to Coppens' at this
      dvl_sound_speed_m_s: null  # temperature); what the DVL (null: its messages', else
      sonar_sound_speed_m_s: 1500 # 1500) and the sonar were set to (undertow.io.sound_speed)
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ..log import FRESH_WATER_DENSITY
from .clock import CLOCK_TOLERANCE_S
from .geo import check_origin
from .sound_speed import DEFAULT_SET_SOUND_SPEED

#: sea water at 10 C and salinity 35 g/kg: 1027 kg/m^3 (UNESCO 1981 equation of state); 1025 is
#: the usual round figure of surface sea water, and what ArduSub's salt-water setting uses
SALT_WATER_DENSITY = 1025.0
WATER_DENSITY = {"fresh": FRESH_WATER_DENSITY, "salt": SALT_WATER_DENSITY}


class LogOptions(BaseModel):
    """How to read a log (see the module docstring); defaults detect from the log."""

    model_config = ConfigDict(extra="forbid")

    time: Literal["auto", "header", "record"] = "auto"
    clock_tolerance_s: float = Field(CLOCK_TOLERANCE_S, gt=0, allow_inf_nan=False)
    imu_units: Literal["auto", "rad/s", "deg/s"] = "auto"
    surface_pressure_pa: float | Literal["auto"] = "auto"
    water: Literal["fresh", "salt"] = "fresh"
    depth_z: Literal["auto", "down", "up"] = "auto"
    gps_origin: tuple[float, float, float] | None = None
    sound_speed_m_s: float | None = Field(None, gt=0, allow_inf_nan=False)
    water_temperature_c: float | None = Field(None, ge=0, le=35, allow_inf_nan=False)
    dvl_sound_speed_m_s: float | None = Field(None, gt=0, allow_inf_nan=False)
    sonar_sound_speed_m_s: float = Field(DEFAULT_SET_SOUND_SPEED, gt=0, allow_inf_nan=False)

    @model_validator(mode="after")
    def _one_sound_speed(self):
        if self.sound_speed_m_s is not None and self.water_temperature_c is not None:
            raise ValueError(
                "give the water's sound_speed_m_s or its water_temperature_c, not both"
            )
        return self

    @field_validator("surface_pressure_pa")
    @classmethod
    def _positive(cls, value):
        if value != "auto" and not (0 < value < 1e7):
            raise ValueError("a pressure in Pa (e.g. 101325) or auto")
        return value

    @field_validator("gps_origin", mode="before")
    @classmethod
    def _origin(cls, value):
        if value is None:
            return None
        if isinstance(value, str):
            value = [v for v in value.replace(",", " ").split() if v]
        return check_origin(value)

    @property
    def water_density_kg_m3(self) -> float:
        return WATER_DENSITY[self.water]
