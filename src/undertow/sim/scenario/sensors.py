"""Sensor, mounting and output parameters of a scenario (pydantic), defaults from the sensor
datasheets and documentation cited in each field. None of them is fitted to the paper's tables."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...robot import DVL_PRESETS, DvlGeometry, Mounting, SensorMount

Vec3 = tuple[float, float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ImuModel(_Model):
    """Gyro and accelerometer given as continuous densities (the convention of Kalibr's "IMU
    Noise Model"): per-sample white sigma_d = sigma_c sqrt(rate); bias walk step =
    sigma_bc / sqrt(rate)."""

    rate_hz: float = Field(100.0, gt=0)
    gyro_noise_density: float = Field(
        1.75e-4, ge=0, description="rad/s/sqrt(Hz); MPU-9250 datasheet 0.01 deg/s/sqrt(Hz)"
    )
    gyro_bias_random_walk: float = Field(
        2.0e-5, ge=0, description="rad/s^2/sqrt(Hz); MEMS order (Kalibr IMU examples)"
    )
    gyro_initial_bias_sigma: float = Field(
        2.0e-3, ge=0, description="rad/s; residual after the autopilot's boot calibration"
    )
    accel_noise_density: float = Field(
        2.9e-3, ge=0, description="m/s^2/sqrt(Hz); MPU-9250 datasheet 300 ug/sqrt(Hz)"
    )


class DvlModel(_Model):
    """The DVL. ``model`` picks a beam-geometry preset (``robot.DVL_PRESETS``: Water Linked A50,
    Nortek DVL1000, Teledyne RDI Pathfinder, from their datasheets); ``beam_tilt_deg``,
    ``beam_azimuths_deg`` and ``beam_width_deg`` left out take the preset's values, given they
    override it. Four beams: the log's DVL stream and both ROS DVL messages carry four."""

    model: Literal["a50", "dvl1000", "pathfinder"] = Field(
        "a50", description="beam geometry preset (datasheet values)"
    )
    rate_hz: float = Field(8.0, gt=0, description="A50 spec: 10 Hz at 0.3-3 m, 5-6 at 1.5-14 m")
    beam_tilt_deg: float = Field(22.5, gt=0, lt=90, description="beam tilt from vertical; preset")
    beam_azimuths_deg: tuple[float, float, float, float] = Field(
        DVL_PRESETS["a50"].azimuths_deg,
        description="beam azimuths about +z from forward toward starboard, beam-id order; preset",
    )
    beam_width_deg: float | None = Field(
        None, gt=0, lt=90, description="one-way -3 dB beam width; recorded, not ray-cast"
    )
    beam_velocity_sigma: float = Field(
        2.0e-3, ge=0, description="m/s per beam; A50 ~1 % of 0.2 m/s, order of magnitude"
    )
    range_sigma: float = Field(5.0e-3, ge=0, description="m per beam range, assumed")
    min_range: float = Field(0.05, ge=0, description="A50 spec: altitude 0.05-50 m")
    max_range: float = Field(50.0, gt=0, description="A50 spec: altitude 0.05-50 m")
    sound_speed_setting: float = Field(
        1500.0,
        gt=0,
        description=(
            "c_set configured in the DVL; 1500 m/s, a sea-water value, left set in the fresh"
            " water (the A50's own get_config example answers 1475 m/s, as the virtual A50)"
        ),
    )
    wave_noise_coefficient: Vec3 = Field(
        (1.0, 0.0, 0.0),
        description=(
            "kappa (along-wave, cross-wave, vertical): extra velocity noise sigma = kappa U/sqrt2,"
            " U the orbital speed amplitude at the DVL depth; only the along-wave axis grows"
            " with wave energy (paper, Table I)."
            " kappa = 1: noise with the orbital velocity's own RMS"
        ),
    )
    wave_noise_sigma: Vec3 | None = Field(
        None, description="m/s (along, cross, vertical); if set, used instead of kappa U/sqrt2"
    )
    wave_range_noise_coefficient: float = Field(
        1.0, ge=0, description="extra range sigma = coeff x vertical orbital displacement RMS"
    )

    @model_validator(mode="before")
    @classmethod
    def _preset(cls, data):
        """Geometry fields not given take the preset's values."""
        model = data.get("model") if isinstance(data, dict) else None
        if isinstance(model, str) and model in DVL_PRESETS:  # a list or a dict is not a name
            preset = DVL_PRESETS[data["model"]]
            data = {"beam_tilt_deg": preset.tilt_deg,
                    "beam_azimuths_deg": preset.azimuths_deg, **data}  # fmt: skip
        return data

    def geometry(self) -> DvlGeometry:
        """The beam geometry this DVL uses (preset name, tilt, azimuths, beam width)."""
        return DvlGeometry(
            self.model, self.beam_tilt_deg, self.beam_azimuths_deg, self.beam_width_deg
        )


class DeadReckoningModel(_Model):
    rate_hz: float = Field(5.0, gt=0, description="A50 position_local rate, assumed")
    yaw_drift_rate: float = Field(
        3.5e-4, description="rad/s; uncalibrated MEMS gyro bias ~0.02 deg/s, assumed"
    )
    roll_pitch_drift_rate: tuple[float, float] = Field(
        (0.0, 0.0), description="rad/s; gravity keeps roll/pitch from drifting"
    )
    orientation_sigma: float = Field(1.0e-3, ge=0, description="rad, white noise per report")


class BarometerModel(_Model):
    rate_hz: float = Field(10.0, gt=0, description="Bar30 as read by ArduSub, ~10 Hz")
    noise_sigma_pa: float = Field(
        20.0, ge=0, description="MS5837-30BA resolution 0.2 mbar (OSR 8192)"
    )


class SonarModel(_Model):
    rate_hz: float = Field(10.0, gt=0, description="Ping2 ~10 Hz at a few metres")
    beam_angle_deg: float = Field(25.0, gt=0, description="Ping2 spec: 25 deg beam")
    fan_rings: int = Field(3, ge=1, description="rings of rays in the cone (plus the axis)")
    fan_azimuths: int = Field(12, ge=3, description="rays per ring")
    range_sigma: float = Field(0.01, ge=0, description="m, assumed")
    range_sigma_fraction: float = Field(5.0e-3, ge=0, description="Ping2 0.5 % of range")
    wave_range_noise_coefficient: float = Field(
        1.0, ge=0, description="extra range sigma = coeff x vertical orbital displacement RMS "
        "(the DVL's wave range term)"
    )  # fmt: skip
    min_range: float = Field(0.3, ge=0, description="Ping2 spec")
    max_range: float = Field(100.0, gt=0, description="Ping2 spec: 100 m range")
    confidence_window: float = Field(
        0.1, gt=0, description="m; confidence = share of cone rays within this of the first return"
    )
    sound_speed_setting: float = Field(
        1500.0,
        gt=0,
        description=(
            "c_set the Ping converts its echo's travel time with (ping-protocol"
            " set_speed_of_sound; 1500 m/s, the Ping1D's default, left set in the fresh water)"
        ),
    )


class MultibeamModel(_Model):
    """A multibeam echosounder: ``beams`` equiangular beams across track over ``swath_deg``,
    one ping every 1 / ``rate_hz`` s (defaults in the range of 400 kHz shallow-water heads:
    R2Sonic 2020, Norbit WBMS, Kongsberg M3 datasheets: 256 beams, 130-160 deg swath, up to
    ~60 Hz ping rate).

    Beam j of a ping: across-track angle theta_j = -swath/2 + j swath/(B - 1), unit vector
    u_j = (0, sin theta_j, cos theta_j) in the sensor frame (x along track, y starboard, z down).
    Range noise: the IHO S-44 (6th ed., 2020) total vertical uncertainty form
    sigma_d = sqrt(a^2 + (b d)^2) at depth d below the head, with d = r cos theta the vertical
    extent of the beam, projected on the beam: sigma_r(r, theta) = sqrt(a^2 + (b r cos theta)^2)
    / cos theta. a and b are one-sigma here (S-44 states them at 95 %, 1.96 sigma); defaults: a
    the order of the R2Sonic 2020's 1.25 cm range resolution, b = 0.2 % of depth (assumed, well
    inside S-44 Special Order's b = 0.0075 at 95 %).
    """

    rate_hz: float = Field(20.0, gt=0, le=100, description="ping rate; 20-60 Hz in shallow water")
    beams: int = Field(256, ge=2, le=1024, description="beams per ping (R2Sonic 2020: 256)")
    swath_deg: float = Field(140.0, gt=0, lt=180, description="total across-track swath")
    range_sigma_a_m: float = Field(0.0125, ge=0, description="a of sigma_d, m (one sigma)")
    range_sigma_b: float = Field(0.002, ge=0, description="b of sigma_d, per metre of depth")
    min_range: float = Field(0.2, ge=0, description="blanking distance, m")
    max_range: float = Field(75.0, gt=0, description="R2Sonic 2020 max range ~ 75 m at 400 kHz")

    def across_angles(self):
        """theta_j (rad, B values, port to starboard)."""
        half = np.deg2rad(self.swath_deg) / 2.0
        return np.linspace(-half, half, self.beams)


class WaveProbeModel(_Model):
    rate_hz: float = Field(100.0, gt=0)
    x_m: float = Field(80.0, description="fixed probe x, ahead of the run (toward the paddle)")
    y_m: float = 0.0
    noise_sigma: float = Field(1.0e-3, ge=0, description="m; resistance wave probe, assumed")


class GroundTruthModel(_Model):
    rate_hz: float = Field(2000.0, gt=0, description="carriage position log rate (paper)")


class FloorCloudModel(_Model):
    spacing_m: float = Field(0.025, gt=0, description="2.5 cm, a dense LiDAR scan")
    margin_m: float = Field(2.0, ge=0, description="around the area the robot covers")
    max_points: int = Field(2_000_000, gt=0)


class SensorMountModel(_Model):
    translation: Vec3 = (0.0, 0.0, 0.0)
    rotation: Vec3 = (0.0, 0.0, 0.0)


class MountingModel(_Model):
    """Lever arms (m, body FRD) and rotations (rad): a public BlueROV2 URDF's values."""

    imu: SensorMountModel = SensorMountModel()
    dvl: SensorMountModel = SensorMountModel(
        translation=(0.164, 0.004, 0.284), rotation=(0, 0, 0.05)
    )
    sonar: SensorMountModel = SensorMountModel(translation=(0.164, 0.106, 0.306))
    barometer: SensorMountModel = SensorMountModel()
    multibeam: SensorMountModel = SensorMountModel(translation=(0.25, 0.0, 0.3))

    def to_mounting(self) -> Mounting:
        return Mounting(
            **{
                name: SensorMount(tuple(m.translation), tuple(m.rotation))
                for name, m in (
                    ("imu", self.imu),
                    ("dvl", self.dvl),
                    ("sonar", self.sonar),
                    ("barometer", self.barometer),
                    ("multibeam", self.multibeam),
                )
            }
        )
