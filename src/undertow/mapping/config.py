"""Mapping configuration (pydantic). Defaults are the paper's mapping-parameters table.

The factory :func:`mapper_from_config` unpacks it into explicit :func:`make_mapper` arguments;
:func:`samples_from_config` does the same for :func:`build_samples`. Core classes never take
the config object.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .._util.validate import validate
from .mappers import L_MAX, L_MIN, Mapper, make_mapper
from .samples import Samples, build_samples

Triple = tuple[float, float, float]


class MappingConfig(BaseModel):
    """Mapping stage settings (grid 0.1 m, sigma_0 DVL 0.9 / sonar 0.6, l_min, l_max)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: Literal["csm", "bki", "adaptive"] = "adaptive"
    resolution: float = Field(0.1, gt=0, allow_inf_nan=False, description="grid size, m")
    length_scale: float = Field(0.15, gt=0, description="isotropic l of the bki method, m")
    l_min: Triple = Field(L_MIN, description="adaptive minimum length scales x, y, z, m")
    l_max: Triple = Field(L_MAX, description="adaptive maximum length scales x, y, z, m")
    alpha0: float = Field(1e-10, gt=0)
    beta0: float = Field(1e-10, gt=0)
    variance_bounds: tuple[Triple, Triple] | None = Field(
        None, description="fixed (min, max) position variance per axis, m^2; None: per session"
    )
    free_resolution: float = Field(0.1, gt=0, description="spacing of free samples, m")
    sigma0_dvl: float = Field(0.9, gt=0)
    sigma0_sonar: float = Field(0.6, gt=0)
    use_dvl: bool = True
    use_sonar: bool = True
    occupied_threshold: float = Field(0.5, ge=0, le=1)
    max_memory_gb: float | None = Field(
        None, gt=0, description="refuse a map whose storage would exceed this, GB; None: half "
        "the machine's RAM"
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> MappingConfig:
        if any(lo <= 0 or lo > hi for lo, hi in zip(self.l_min, self.l_max, strict=True)):
            raise ValueError(f"need 0 < l_min <= l_max per axis, got {self.l_min} / {self.l_max}")
        if self.variance_bounds is not None and any(
            lo < 0 or lo > hi for lo, hi in zip(*self.variance_bounds, strict=True)
        ):
            raise ValueError("variance_bounds need 0 <= min <= max per axis")
        if not (self.use_dvl or self.use_sonar):
            raise ValueError(
                "use_dvl and use_sonar are both false in the config: enable at least one range "
                "stream"
            )
        lengths = {"bki": ("length_scale", (self.length_scale,)), "adaptive": ("l_min", self.l_min)}
        name, values = lengths.get(self.method, ("", ()))
        if any(v <= self.resolution / 10 for v in values):
            raise ValueError(
                f"{name} {values if len(values) > 1 else values[0]} m is not above resolution / "
                f"10 = {self.resolution / 10:g} m: use a finer resolution or longer length scales"
            )
        return self

    @classmethod
    def from_dict(cls, data: dict) -> MappingConfig:
        """Validate a dict; errors become one-line :class:`ConfigError`."""
        return validate(cls, data, "mapping.")


def mapper_from_config(config: MappingConfig, prior=None) -> Mapper:
    """``make_mapper`` with the config's values."""
    return make_mapper(
        config.method, resolution=config.resolution, length_scale=config.length_scale,
        l_min=config.l_min, l_max=config.l_max, alpha0=config.alpha0, beta0=config.beta0,
        variance_bounds=config.variance_bounds, prior=prior, max_memory_gb=config.max_memory_gb,
    )  # fmt: skip


def samples_from_config(log, trajectory, config: MappingConfig) -> Samples:
    """``build_samples`` with the config's values."""
    return build_samples(
        log, trajectory, free_resolution=config.free_resolution, sigma0_dvl=config.sigma0_dvl,
        sigma0_sonar=config.sigma0_sonar, use_dvl=config.use_dvl, use_sonar=config.use_sonar,
    )  # fmt: skip
