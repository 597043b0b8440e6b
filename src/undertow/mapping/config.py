"""Mapping configuration (pydantic): the one place the mapping parameters get their defaults
(the paper's mapping-parameters table) and are checked.

:func:`~undertow.mapping.mappers.mapper_from_config` and
:func:`~undertow.mapping.samples.samples_from_config` unpack it into the explicit, already
checked arguments of the mapper classes and of the sample builder; those hold no defaults of
their own.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from .._util.validate import validate
from ..occupancy import OCCUPIED_THRESHOLD

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]


def _as_sequence(value):
    """numpy arrays are accepted where a tuple is expected (the model stores tuples)."""
    return value.tolist() if isinstance(value, np.ndarray) else value


def _three(value):
    value = _as_sequence(value)
    if isinstance(value, list | tuple) and len(value) != 3:
        raise ValueError(f"expected three values (x, y, z), got {len(value)}")
    return value


Triple = Annotated[tuple[Finite, Finite, Finite], BeforeValidator(_three)]
Method = Literal["csm", "bki", "adaptive", "tpu"]


#: the map's chunks kept in memory by default, MB (mapping.resident_mb): 16 384 chunks of 8^3
#: cells, e.g. 8 000 m^3 of mapped volume at 0.1 m cells around the vehicle; a Raspberry Pi 4
#: (4-8 GB) runs the filter, the map and the view of a dive of hours in a few hundred MB
RESIDENT_MB = 64.0


class MappingConfig(BaseModel):
    """Mapping stage settings (grid 0.1 m, sigma_0 DVL 0.9 / sonar 0.6 / multibeam 0.6, l_min,
    l_max). A multibeam stream, when the log has one, is mapped unless ``use_multibeam`` is
    false; a multibeam-only map (use_dvl and use_sonar false) sets ``use_multibeam: true``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: Method = "tpu"
    resolution: float = Field(0.1, gt=0, allow_inf_nan=False, description="grid size, m")
    length_scale: float = Field(
        0.15, gt=0, allow_inf_nan=False, description="isotropic l of the bki method, m"
    )
    l_min: Triple = Field((0.10, 0.10, 0.05), description="adaptive minimum length scales, m")
    l_max: Triple = Field((0.18, 0.18, 0.08), description="adaptive maximum length scales, m")
    base_length: float = Field(
        0.10, gt=0, allow_inf_nan=False,
        description="tpu: across-floor length scale of a perfectly placed hit, m (paper's l_min)",
    )  # fmt: skip
    max_length: float = Field(
        2.0, gt=0, allow_inf_nan=False,
        description="tpu: largest across-floor length scale, m (bounds the cost and tile halo)",
    )  # fmt: skip
    range_std_dvl: float = Field(
        0.005, gt=0, allow_inf_nan=False,
        description="tpu: DVL beam range noise, m (not in the A50's spec: assumed)",
    )  # fmt: skip
    range_std_sonar: float = Field(
        0.01, gt=0, allow_inf_nan=False, description="tpu: sonar range noise s_0, m (assumed)"
    )
    range_std_multibeam: float = Field(
        0.01, gt=0, allow_inf_nan=False, description="tpu: multibeam range noise s_0, m (assumed)"
    )
    range_std_fraction: float = Field(
        0.005, ge=0, allow_inf_nan=False,
        description="tpu: sonar and multibeam range noise per metre of range (Ping2: 0.5 %)",
    )  # fmt: skip
    sonar_beam_width_deg: float = Field(
        25.0, ge=0, lt=180, allow_inf_nan=False,
        description="tpu: the sonar's full beam width, deg (Ping2 spec: 25)",
    )  # fmt: skip
    sonar_carve: bool = Field(
        True, description="tpu: each sonar first return clears its cone nearer than its range, "
        "so a return from relief beside the axis does not widen it (mapping.carve)",
    )  # fmt: skip
    wave_range_noise: bool = Field(
        True, description="tpu: add the waves' orbital displacement (the trajectory's wave) "
        "to the range noise",
    )  # fmt: skip
    wave: Annotated[tuple[Finite, Finite] | None, BeforeValidator(_as_sequence)] = Field(
        None, description="tpu: (amplitude m, frequency Hz) of that wave; None: the "
        "trajectory's (mapping.tpu.with_wave)",
    )  # fmt: skip
    wave_depth_noise: bool = Field(
        True, description="tpu: add the swell's pressure the trajectory's depth carries, as its "
        "filter passed it on, to the pose's depth variance (mapping.depth_wave)",
    )  # fmt: skip
    depth_noise: Annotated[tuple[Positive, Positive] | None, BeforeValidator(_as_sequence)] = (
        Field(None, description="tpu: (std m, sample interval s) of the depth measurements the "
              "trajectory's filter fused; None: the trajectory's (its depth_std_m and pressure "
              "updates), none when its filter carried the swell "
              "(pressure_wave_noise)")
    )  # fmt: skip
    alpha0: float = Field(1e-10, gt=0, allow_inf_nan=False)
    beta0: float = Field(1e-10, gt=0, allow_inf_nan=False)
    variance_bounds: Annotated[tuple[Triple, Triple] | None, BeforeValidator(_as_sequence)] = Field(
        None,
        description="fixed (min, max) position variance per axis, m^2; None: per session",
    )
    free_resolution: float = Field(
        0.1, gt=0, allow_inf_nan=False, description="spacing of free samples, m"
    )
    sigma0_dvl: float = Field(0.9, gt=0, allow_inf_nan=False)
    sigma0_sonar: float = Field(0.6, gt=0, allow_inf_nan=False)
    sigma0_multibeam: float = Field(
        0.6, gt=0, allow_inf_nan=False, description="sigma_0 of multibeam samples (as the sonar)"
    )
    use_dvl: bool = True
    use_sonar: bool = True
    use_multibeam: bool = True
    occupied_threshold: float = Field(OCCUPIED_THRESHOLD, ge=0, le=1)
    max_memory_gb: float | None = Field(
        None, gt=0, allow_inf_nan=False, description="refuse a map whose storage would exceed "
        "this, GB; None: half the machine's RAM"
    )  # fmt: skip
    resident_mb: float | None = Field(
        RESIDENT_MB, gt=0, allow_inf_nan=False, description="the most the map's chunks keep "
        "in memory, MB; beyond it the tiles farthest from the latest write move to a temporary "
        "file and come back when written again (the same map); None: all in memory"
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> MappingConfig:
        if any(lo <= 0 or lo > hi for lo, hi in zip(self.l_min, self.l_max, strict=True)):
            raise ValueError(f"need 0 < l_min <= l_max per axis, got {self.l_min} / {self.l_max}")
        if self.variance_bounds is not None and any(
            lo < 0 or lo > hi for lo, hi in zip(*self.variance_bounds, strict=True)
        ):
            raise ValueError("variance_bounds need 0 <= min <= max per axis")
        multibeam_only = self.use_multibeam and "use_multibeam" in self.model_fields_set
        if not (self.use_dvl or self.use_sonar or multibeam_only):
            raise ValueError(
                "use_dvl and use_sonar are both false in the config: enable at least one range "
                "stream (use_multibeam: true for a multibeam-only map)"
            )
        # a length scale under a tenth of a cell puts a sample's kernel mass in at most one
        # cell centre, or none: the map would lose its samples
        lengths = {"bki": ("length_scale", (self.length_scale,)), "adaptive": ("l_min", self.l_min),
                   "tpu": ("base_length", (self.base_length,))}  # fmt: skip
        name, values = lengths.get(self.method, ("", ()))
        if any(v <= self.resolution / 10 for v in values):
            raise ValueError(
                f"{name} {values if len(values) > 1 else values[0]} m is not above resolution / "
                f"10 = {self.resolution / 10:g} m: use a finer resolution or longer length scales"
            )
        if self.base_length > self.max_length:
            raise ValueError(
                f"base_length {self.base_length} m exceeds max_length {self.max_length} m"
            )
        return self

    @classmethod
    def from_dict(cls, data: dict) -> MappingConfig:
        """Validate a dict; errors become one-line :class:`ConfigError`."""
        return validate(cls, data, "mapping.")
