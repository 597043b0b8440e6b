"""Scenarios: every parameter of a simulation, as pydantic models with documented defaults.

A scenario is a YAML file; any field left out takes the default below, and ``base: NAME`` starts
from a built-in scenario (deep merge) so a user file can change a single field. The built-ins
live in ``undertow/data/scenarios/*.yaml``. Sensor models are in ``sensors.py`` (this package);
the cross-field checks that reject physically impossible scenarios (robot out of the water or
below the floor, a run leaving the tank, a breaking wave, ...) in ``checks.py``. The seabed
(``floor``: flat, procedural or from a bathymetry file) is built by ``sim/seabed.py``; a relative
``floor.file`` is relative to the scenario file that names it.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from ..._util.validate import read_yaml, validate
from ...errors import ConfigError
from ...log import FRESH_WATER_DENSITY
from .sensors import (
    BarometerModel,
    DeadReckoningModel,
    DvlModel,
    FloorCloudModel,
    GroundTruthModel,
    ImuModel,
    MountingModel,
    MultibeamModel,
    SonarModel,
    WaveProbeModel,
)


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _invalid(message: str) -> PydanticCustomError:
    """A validation error whose message is shown as is (no "Value error, " prefix)."""
    return PydanticCustomError("invalid_floor", "{message}", {"message": message})


class WaterModel(_Model):
    depth_m: float = Field(3.0, gt=0, description="still-water depth h; UMich MHL tank ~3 m deep")
    density_kg_m3: float = Field(
        FRESH_WATER_DENSITY,
        gt=0,
        description="fresh water at ~20 C (15-20 C: 999.1-998.2); log.FRESH_WATER_DENSITY",
    )
    gravity_m_s2: float = Field(9.80665, gt=0, description="standard gravity")
    sound_speed_m_s: float = Field(
        1476.0,
        gt=0,
        description="true c: fresh water 15 C 1466 m/s, 20 C 1482 m/s (Del Grosso/Marczak 1997)",
    )
    surface_pressure_pa: float = Field(101_325.0, description="standard atmosphere")


class WaveSegmentModel(_Model):
    """One condition of a sea-state schedule, reached by a linear ramp from the one before."""

    amplitude_m: float = Field(ge=0, description="a held in this segment; 0 = calm")
    frequency_hz: float | None = Field(
        None, gt=0, description="f; default: the previous segment's (the first: wave.frequency_hz)"
    )
    ramp_s: float = Field(
        0.0,
        ge=0,
        description="linear ramp in a and f from the previous condition, starting at the previous"
        " segment's until_s (the first segment: from calm at t = 0); >= 2 wave periods",
    )
    until_s: float | None = Field(
        None, gt=0, description="when this condition ends (the next ramp starts); last: run end"
    )


class WaveModel(_Model):
    amplitude_m: float = Field(0.0, ge=0, description="a; 0 = calm (paper: 0.05, 0.1)")
    frequency_hz: float = Field(1.0, gt=0, description="f (paper: 0.75, 1.0)")
    heading_deg: float = Field(
        180.0, description="propagation direction beta in world x-y; 180 = oncoming (toward -x)"
    )
    phase_rad: float = Field(0.0, description="phi_0 of theta = k x - omega t + phi_0")
    schedule: list[WaveSegmentModel] | None = Field(
        None,
        min_length=1,
        description="sea state changing during the run (segments in time order; then"
        " amplitude_m must be 0); the phase is exact at the wave probe (sim/wavefield.py)",
    )


class RockModel(_Model):
    """Rock platform of known size (the paper gives its dimensions only in a figure; these
    defaults are assumed, of the same order)."""

    center_x_m: float = 48.0
    center_y_m: float = 0.3
    length_m: float = Field(1.0, gt=0)
    width_m: float = Field(0.8, gt=0)
    height_m: float = Field(0.4, gt=0)
    edge_radius_m: float = Field(0.05, ge=0, description="fillet radius of the top edges")


class BeachModel(_Model):
    """Plane wave-absorbing beach at the x = 0 end (the waves run toward -x), from the floor at
    x = length_m up to the still-water line at x = 0 (sim/seabed.py)."""

    length_m: float = Field(
        0.0, ge=0, description="0 = no beach; basins' plane beaches slope ~1:4-1:10 (Hughes 1993)"
    )


class TankModel(_Model):
    """The basin (or, without walls, the field's domain: the area the floor is defined over)."""

    length_m: float = Field(110.0, gt=0, description="UMich MHL towing tank, 360 ft")
    width_m: float = Field(6.7, gt=0, description="UMich MHL towing tank, 22 ft")
    rock: RockModel = RockModel()
    walls: bool = Field(
        True, description="side and end walls at the domain's edges (false: open water, the"
        " floor's edge values continue outside)"
    )  # fmt: skip
    beach: BeachModel = BeachModel()


class SlopeModel(_Model):
    """Plane through the still-water depth h at the reference point, deepening toward
    ``downslope_deg`` (sim/seabed.py). Shelf and coastal slopes 0.1-5 deg, below sand's angle of
    repose ~32 deg (Soulsby 1997, "Dynamics of Marine Sands")."""

    gradient_deg: float = Field(0.0, ge=0, lt=30, description="slope angle alpha; 0.1-5 deg")
    downslope_deg: float = Field(0.0, description="direction the floor deepens, from +x to +y")
    reference_x_m: float | None = Field(None, description="where z = h; default domain centre")
    reference_y_m: float | None = Field(None, description="where z = h; default domain centre")


class RipplesModel(_Model):
    """Sinusoidal sand ripples; wave ripples: wavelength 0.1-1 m, height 0.01-0.15 m, steepness
    height / wavelength <= 0.2 (Soulsby 1997 sec. 7.2; Nielsen 1992, "Coastal Bottom Boundary
    Layers and Sediment Transport")."""

    wavelength_m: float = Field(0.5, gt=0, description="lambda_r, 0.1-1 m")
    height_m: float = Field(0.0, ge=0, description="crest to trough eta_r, 0.01-0.15 m; 0 = none")
    crest_deg: float = Field(90.0, description="direction the crest lines run, from +x to +y")
    phase_deg: float = Field(0.0, description="phi_r; 0 = a crest through the origin")

    @model_validator(mode="after")
    def _steepness(self) -> RipplesModel:
        if self.height_m > 0.2 * self.wavelength_m:
            raise _invalid(
                f"height_m {self.height_m} m over wavelength_m {self.wavelength_m} m is steeper"
                " than sand ripples stand (height / wavelength <= 0.2, Soulsby 1997)"
            )
        return self


class RoughnessModel(_Model):
    """Seeded Gaussian random field, spectrum W(K) ~ K^-gamma between the two wavelengths,
    RMS height rms_m (Jackson & Richardson 2007, "High-Frequency Seafloor Acoustics": measured
    gamma ~ 2.5-3.5, RMS ~ 0.005-0.05 m)."""

    rms_m: float = Field(0.0, ge=0, description="RMS height sigma, 0.005-0.05 m; 0 = none")
    spectral_slope: float = Field(3.0, gt=0, le=5, description="gamma of W(K) ~ K^-gamma, 2-4")
    min_wavelength_m: float = Field(0.1, gt=0, description="shortest wavelength (>= 2 nodes)")
    max_wavelength_m: float = Field(5.0, gt=0, description="longest wavelength (<= the domain)")

    @model_validator(mode="after")
    def _band(self) -> RoughnessModel:
        if self.min_wavelength_m >= self.max_wavelength_m:
            raise _invalid(
                f"min_wavelength_m {self.min_wavelength_m} m must be below max_wavelength_m"
                f" {self.max_wavelength_m} m"
            )
        return self


class BoxRockModel(_Model):
    """A box with rounded top edges resting on the floor (like the tank's rock platform)."""

    kind: Literal["box"] = "box"
    center_x_m: float
    center_y_m: float
    length_m: float = Field(gt=0)
    width_m: float = Field(gt=0)
    height_m: float = Field(gt=0, description="above the floor under its centre")
    edge_radius_m: float = Field(0.05, ge=0, description="fillet of the top edges")
    yaw_deg: float = Field(0.0, description="length axis from +x toward +y")

    @model_validator(mode="after")
    def _fillet(self) -> BoxRockModel:
        if 2 * self.edge_radius_m > min(self.length_m, self.width_m, 2 * self.height_m):
            raise _invalid(
                f"edge_radius_m {self.edge_radius_m} m: the fillet must fit the rock (at most"
                " half its length and width, and its height)"
            )
        return self


class BoulderModel(_Model):
    """An ellipsoidal boulder: the upper half of an ellipsoid of these full axes resting on the
    floor; boulders are clasts over 0.256 m (Wentworth 1922)."""

    kind: Literal["boulder"] = "boulder"
    center_x_m: float
    center_y_m: float
    length_m: float = Field(gt=0, description="full axis along yaw, 0.25-4 m")
    width_m: float = Field(gt=0, description="full axis across yaw, 0.25-4 m")
    height_m: float = Field(gt=0, description="above the floor (the vertical semi-axis)")
    yaw_deg: float = Field(0.0, description="length axis from +x toward +y")


RockSpec = Annotated[BoxRockModel | BoulderModel, Field(discriminator="kind")]
_PROCEDURAL_KEYS = ("slope", "ripples", "roughness")


class FloorModel(_Model):
    """The seabed (sim/seabed.py): ``flat`` (the original tank's floor at water.depth_m with the
    rock platform), ``procedural`` (plane, ripples, roughness, rocks) or ``file`` (a GeoTIFF,
    XYZ or PLY bathymetry placed by offset_m and rotation_deg). Every form but the original
    flat tank is a heightfield of node spacing resolution_m over the tank (tank.length_m x
    tank.width_m), the tank's rock platform included. ``kind`` may be left out: ``file`` when
    ``file`` is set, ``procedural`` when a procedural field is."""

    kind: Literal["flat", "procedural", "file"] = "flat"
    resolution_m: float = Field(
        0.025, gt=0, le=1.0, description="heightfield node spacing; a quarter of a 0.1 m map cell"
    )
    seed: int = Field(
        0, ge=0, description="roughness seed: the seabed, fixed while the run's seed varies"
    )
    slope: SlopeModel = SlopeModel()
    ripples: RipplesModel = RipplesModel()
    roughness: RoughnessModel = RoughnessModel()
    rocks: list[RockSpec] = Field([], description="boxes and boulders on the floor")
    file: str | None = Field(None, description="GeoTIFF (.tif), XYZ text or PLY bathymetry")
    values: Literal["elevation", "depth"] = Field(
        "elevation", description="file values: elevation (positive up) or depth (positive down)"
    )
    offset_m: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="file frame origin in the scenario (x, y) and z: depth ="
        " z - elevation or z + depth"
    )  # fmt: skip
    rotation_deg: float = Field(0.0, description="file frame rotation about z, x toward y")

    @model_validator(mode="before")
    @classmethod
    def _infer_kind(cls, data):
        if isinstance(data, dict) and "kind" not in data:
            if data.get("file") is not None:
                data = {**data, "kind": "file"}
            elif any(k in data for k in (*_PROCEDURAL_KEYS, "rocks")):
                data = {**data, "kind": "procedural"}
        return data

    @model_validator(mode="after")
    def _consistent(self) -> FloorModel:
        if self.kind == "file" and self.file is None:
            raise _invalid("kind file needs floor.file (a GeoTIFF, XYZ or PLY bathymetry)")
        if self.kind != "file" and self.file is not None:
            raise _invalid(f"floor.file is set but kind is {self.kind!r}; use kind: file")
        shaped = (self.slope, self.ripples, self.roughness) != (
            SlopeModel(),
            RipplesModel(),
            RoughnessModel(),
        )
        if self.kind == "flat" and (self.rocks or shaped):
            raise _invalid("slope, ripples, roughness and rocks need kind: procedural")
        if self.kind == "file" and shaped:
            raise _invalid(
                "slope, ripples and roughness need kind: procedural (a file floor takes rocks only)"
            )
        rg = self.roughness
        if rg.rms_m > 0 and rg.min_wavelength_m < 2 * self.resolution_m:
            raise _invalid(
                f"roughness.min_wavelength_m {rg.min_wavelength_m} m is below two nodes of"
                f" resolution_m {self.resolution_m} m (the grid cannot hold it)"
            )
        return self


class MountLoadModel(_Model):
    """Rigid carriage mount shaken by wave loads (Morison): the strut is a stiff spring of
    stiffness K whose natural frequency is far above the wave frequency, so the along-wave
    deflection is quasi-static, delta = F / K, with F the wave part of the Morison force."""

    stiffness_n_m: float = Field(
        2.0e4, gt=0, description="strut bending stiffness; ~2 m aluminium tube, assumed"
    )
    displaced_volume_m3: float = Field(0.0115, gt=0, description="BlueROV2 ~11.5 kg neutrally")
    inertia_coefficient: float = Field(2.0, ge=0, description="C_M = 1 + C_a, bluff body")
    drag_coefficient: float = Field(1.0, ge=0, description="C_D of a bluff box")
    frontal_area_m2: float = Field(0.085, gt=0, description="BlueROV2 0.25 m x 0.34 m")


class CarriageModel(_Model):
    start_x_m: float = Field(30.0, description="carriage start x in the tank")
    y_m: float = 0.0
    depth_m: float = Field(0.5, description="body-origin depth, assumed (the paper gives none)")
    run_length_m: float = Field(
        36.6, ge=0, description="paper: 36.6 m along x; 0 = station keeping (at rest)"
    )
    cruise_speed_m_s: float = Field(1.0, gt=0, description="assumed; below the A50 maximum")
    acceleration_m_s2: float = Field(0.5, gt=0, description="assumed carriage acceleration")
    hold_before_s: float = Field(5.0, ge=0, description="at rest before the run")
    hold_after_s: float = Field(5.0, ge=0, description="at rest after the run")
    mount: MountLoadModel = MountLoadModel()


class SurveyModel(_Model):
    """Free vehicle: lawnmower passes along x over the rock, carried by the orbital flow."""

    start_x_m: float = Field(45.0, description="x where each pass starts")
    pass_length_m: float = Field(6.0, gt=0)
    passes: int = Field(4, ge=1)
    pass_spacing_m: float = Field(0.6, gt=0, description="y step between passes (turn diameter)")
    first_pass_y_m: float = -0.6
    depth_m: float = Field(0.6, description="commanded body depth")
    speed_m_s: float = Field(0.4, gt=0, description="BlueROV2 survey speed, assumed")
    ramp_s: float = Field(2.0, ge=0, description="speed ramp at start and end")
    hold_before_s: float = Field(3.0, ge=0)
    hold_after_s: float = Field(3.0, ge=0)
    attitude_gain: float = Field(
        0.5, ge=0, description="roll/pitch = gain x local orbital-path slope, assumed"
    )


class WaypointsModel(_Model):
    """Free vehicle following straight legs between way points at constant depth, the corners
    rounded with a turn radius (finite yaw rate V / r), carried by the orbital flow like the
    survey; ``laps`` repeats the polyline (close it: last point = first)."""

    points: list[tuple[float, float]] = Field(
        [(40.0, -1.0), (56.0, -1.0), (56.0, 1.0), (40.0, 1.0), (40.0, -1.0)],
        min_length=2,
        description="(x, y) way points, m",
    )
    laps: int = Field(1, ge=1, description="times the polyline is followed")
    turn_radius_m: float = Field(0.5, gt=0, description="radius of the rounded corners")
    depth_m: float = Field(0.6, description="commanded body depth")
    speed_m_s: float = Field(0.5, gt=0, description="BlueROV2 cruise speed, assumed")
    ramp_s: float = Field(2.0, ge=0, description="speed ramp at start and end")
    hold_before_s: float = Field(3.0, ge=0)
    hold_after_s: float = Field(3.0, ge=0)
    attitude_gain: float = Field(
        0.5, ge=0, description="roll/pitch = gain x local orbital-path slope, assumed"
    )


class MotionModel(_Model):
    kind: Literal["carriage", "survey", "waypoints"] = "carriage"
    carriage: CarriageModel = CarriageModel()
    survey: SurveyModel = SurveyModel()
    waypoints: WaypointsModel = WaypointsModel()


class Scenario(_Model):
    """Everything a simulation uses; ``to_yaml_dict()`` writes it back."""

    name: str = "custom"
    description: str = ""
    seed: int = Field(0, ge=0, description="random seed (numpy SeedSequence: non-negative)")
    water: WaterModel = WaterModel()
    wave: WaveModel = WaveModel()
    tank: TankModel = TankModel()
    motion: MotionModel = MotionModel()
    mounting: MountingModel = MountingModel()
    imu: ImuModel = ImuModel()
    dvl: DvlModel = DvlModel()
    dead_reckoning: DeadReckoningModel = DeadReckoningModel()
    barometer: BarometerModel = BarometerModel()
    sonar: SonarModel = SonarModel()
    wave_probe: WaveProbeModel = WaveProbeModel()
    ground_truth: GroundTruthModel = GroundTruthModel()
    floor_cloud: FloorCloudModel = FloorCloudModel()
    floor: FloorModel = FloorModel()
    multibeam: MultibeamModel | None = Field(
        None, description="a multibeam echosounder (none unless given)"
    )

    @model_validator(mode="after")
    def _physically_possible(self) -> Scenario:
        from .checks import check_scenario

        check_scenario(self)
        return self

    def to_yaml_dict(self) -> dict:
        """Plain dict of every field (defaults included), YAML-safe."""
        return self.model_dump(mode="json")


def _builtin_dir():
    return resources.files("undertow") / "data" / "scenarios"


def list_scenarios() -> list[str]:
    """Names of the built-in scenarios."""
    return sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".yaml"))


def _deep_merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def _read_yaml(path, label: str) -> dict:
    try:
        data = read_yaml(path, "scenario YAML file")
    except ConfigError as exc:
        raise ConfigError(str(exc).replace(str(path), label, 1)) from None
    if data is None:  # an empty file (or only comments) is more likely a mistake than a request
        raise ConfigError(
            f"{label}: empty scenario file; name what to simulate, e.g. 'base: calm'"
            f" (built-ins: {', '.join(list_scenarios())})"
        )
    if not isinstance(data, dict):
        raise ConfigError(f"{label}: a scenario file must be a mapping of fields")
    return data


def _is_file(path) -> bool:
    """``path.is_file()``, False for a name the OS refuses (too long, a NUL byte)."""
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


def _raw(name_or_path: str | Path, depth: int = 0) -> tuple[dict, str]:
    text = str(name_or_path)
    builtin = _builtin_dir() / f"{text}.yaml"
    if "/" not in text and _is_file(builtin):
        data, label = _read_yaml(builtin, f"scenario {text}"), f"built-in scenario {text}"
    elif _is_file(text):
        data, label = _read_yaml(Path(text), text), text
    else:
        names = ", ".join(list_scenarios())
        raise ConfigError(f"unknown scenario {text!r}: not a file; built-ins are: {names}")
    _resolve_floor_file(data, builtin.parent if label.startswith("built-in") else Path(text).parent)
    base = data.pop("base", None)
    if base is not None:
        if not isinstance(base, str):
            raise ConfigError(
                f"{label}: field base: the name of a scenario or a file, got {base!r:.40}"
            )
        if depth > 8:
            raise ConfigError(f"{label}: field base: too deep a chain of base scenarios")
        try:
            parent, _ = _raw(base, depth + 1)
        except ConfigError as exc:  # name the user's file first: that is where base is set
            message = str(exc)
            if message.startswith(f"{label}: "):
                raise
            raise ConfigError(f"{label}: field base: {message}") from None
        if _floor_kind(data.get("floor")) not in (None, _floor_kind(parent.get("floor"))):
            parent = {k: v for k, v in parent.items() if k != "floor"}  # a new floor replaces it
        data = _deep_merge(parent, data)
    return data, label


def _floor_kind(floor) -> str | None:
    """The kind a ``floor`` mapping sets or implies (FloorModel's inference), None if neither."""
    if not isinstance(floor, dict):
        return None
    if floor.get("kind") is not None:
        return floor["kind"]
    if floor.get("file") is not None:
        return "file"
    return "procedural" if any(k in floor for k in (*_PROCEDURAL_KEYS, "rocks")) else None


def _resolve_floor_file(data: dict, folder) -> None:
    """A relative ``floor.file`` is relative to the scenario file that names it (in place)."""
    floor = data.get("floor")
    if isinstance(floor, dict) and isinstance(floor.get("file"), str):
        path = Path(floor["file"]).expanduser()
        if not path.is_absolute():
            floor["file"] = str(Path(str(folder)) / path)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name, or a YAML file (fields left out keep their defaults)."""
    data, label = _raw(name_or_path)
    return validate(Scenario, data, f"{label}: field ")
