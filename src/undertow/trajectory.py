"""A Trajectory: filter (or smoother) output, the hand-off from localization to mapping.

State layout (the paper's ``eq:state`` to ``eq:gyro_bias``), 18 entries:

    x = [eta (x, y, z, phi, theta, psi; world), nu (u, v, w, p, q, r; body),
         b^g (dead-reckoning orientation bias, 3), b-bar^g (IMU gyro bias, 3)]

Positions in m (world, z down), angles in rad, velocities in m/s and rad/s.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._util.atomic import atomic_path
from ._util.plain import to_plain
from .errors import ReaderError

STATE_NAMES = (
    "x", "y", "z", "roll", "pitch", "yaw",
    "u", "v", "w", "p", "q", "r",
    "b_dr_roll", "b_dr_pitch", "b_dr_yaw",
    "b_imu_p", "b_imu_q", "b_imu_r",
)  # fmt: skip
POSITION = slice(0, 3)
ORIENTATION = slice(3, 6)
LINEAR_VELOCITY = slice(6, 9)
ANGULAR_VELOCITY = slice(9, 12)
DR_BIAS = slice(12, 15)
GYRO_BIAS = slice(15, 18)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Estimated states ``x`` (N, 18) with covariances ``P`` (N, 18, 18) at times ``t`` (N,)."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    variant: str = ""
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        x = np.asarray(self.x, dtype=np.float64)
        P = np.asarray(self.P, dtype=np.float64)
        n = t.size
        if x.shape != (n, len(STATE_NAMES)) or P.shape != (n, len(STATE_NAMES), len(STATE_NAMES)):
            raise ValueError(f"Trajectory: x {x.shape} / P {P.shape} do not match {n} times")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "P", P)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def position(self) -> np.ndarray:
        return self.x[:, POSITION]

    @property
    def orientation(self) -> np.ndarray:
        return self.x[:, ORIENTATION]

    @property
    def velocity_body(self) -> np.ndarray:
        return self.x[:, LINEAR_VELOCITY]

    @property
    def position_variance(self) -> np.ndarray:
        """Per-axis position variance (N, 3), m^2: the diagonal of P's position block."""
        return np.einsum("nii->ni", self.P[:, POSITION, POSITION])

    def save_npz(self, path: str | Path) -> Path:
        """Write times, full state, full covariance and the metadata (a JSON string, so that
        e.g. :func:`~undertow.estimation.smooth` can run on a loaded trajectory); atomic: temp
        file then rename."""
        path = Path(path)
        metadata = json.dumps(to_plain(self.metadata), default=str)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                t=self.t,
                x=self.x,
                P=self.P,
                state_names=np.array(STATE_NAMES),
                variant=np.array(self.variant),
                metadata_json=np.array(metadata),
                **wave_arrays(self.metadata),
            )
        return path

    @classmethod
    def load_npz(cls, path: str | Path) -> Trajectory:
        """Read a trajectory written by :meth:`save_npz` (a directory means DIR/trajectory.npz)."""
        path = Path(path)
        if path.is_dir():
            path = path / "trajectory.npz"
        check_npz(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                metadata = {}
                if "metadata_json" in data.files:  # older files have none
                    metadata = json.loads(str(data["metadata_json"]))
                    if not isinstance(metadata, dict):
                        raise ValueError("metadata_json is not a JSON object")
                return cls(
                    t=data["t"],
                    x=data["x"],
                    P=data["P"],
                    variant=str(data["variant"]),
                    metadata=metadata,
                )
        except FileNotFoundError as exc:
            raise ReaderError(f"{path}: no such trajectory file") from exc
        except (KeyError, ValueError, OSError, zipfile.BadZipFile) as exc:
            raise ReaderError(f"{path}: {_NOT_NPZ} ({exc})") from exc

    def replace(self, **changes) -> Trajectory:
        return dataclasses.replace(self, **changes)


_NOT_NPZ = "not a trajectory.npz written by `undertow localize`"


def wave_arrays(metadata: dict) -> dict:
    """The wave condition the filter followed over time (metadata ``wave_track``, e.g. from
    ``--wave auto``) as arrays ``wave_t``, ``wave_amplitude_m``, ``wave_frequency_hz`` (NaN
    where calm); none for a constant condition."""
    track = metadata.get("wave_track")
    if not isinstance(track, dict) or "t" not in track:
        return {}
    f = [np.nan if v is None else v for v in track.get("frequency_hz", [])]
    return {
        "wave_t": np.asarray(track["t"], float),
        "wave_amplitude_m": np.asarray(track["amplitude_m"], float),
        "wave_frequency_hz": np.asarray(f, float),
    }


def check_npz(path: Path) -> None:
    """A file that is not a zip archive (an .npz is one) is refused before numpy reads it, which
    would talk about pickled data: a TUM file in particular holds poses without covariances."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except FileNotFoundError:
        raise ReaderError(f"{path}: no such trajectory file") from None
    except IsADirectoryError:
        raise ReaderError(f"{path}: {_NOT_NPZ} (a folder without trajectory.npz)") from None
    except OSError as exc:
        raise ReaderError(f"{path}: cannot read trajectory: {exc.strerror or exc}") from None
    if head == b"PK\x03\x04":
        return
    if head == b"PK\x05\x06":  # an empty zip archive
        raise ReaderError(f"{path}: {_NOT_NPZ} (an empty archive)")
    tum = path.suffix.lower() in (".tum", ".txt") or _looks_like_text(path)
    hint = (
        " (a TUM file has poses only, no covariances; give the localize output folder or its "
        "trajectory.npz)"
        if tum
        else ""
    )
    raise ReaderError(f"{path}: {_NOT_NPZ}{hint}")


def _looks_like_text(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            fh.read(4096).decode("ascii")
    except (OSError, UnicodeDecodeError):
        return False
    return True
