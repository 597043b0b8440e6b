"""An ``.npz`` archive written member by member and part by part, for arrays larger than
memory: each streamed member's ``.npy`` header first (its shape known from a count), then its
parts' bytes, deflated as ``numpy.savez_compressed`` does; ``numpy.load`` reads it as any npz."""

from __future__ import annotations

import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from .._util.atomic import atomic_path
from ..errors import DataError

#: a streamed member: (dtype, shape, a function giving its parts (arrays whose rows, in order,
#: make the member))
Streamed = tuple[np.dtype, tuple, Callable[[], Iterable[np.ndarray]]]


def write_npz_parts(path, streamed: dict[str, Streamed], small: dict[str, np.ndarray]) -> Path:
    """``path`` (atomic) with the ``streamed`` members, then the ``small`` ones (written
    whole); a streamed member whose parts do not hold its shape's bytes is an error."""
    path = Path(path)
    with (
        atomic_path(path) as tmp,
        zipfile.ZipFile(tmp, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf,
    ):
        for name, (dtype, shape, parts) in streamed.items():
            dtype = np.dtype(dtype)
            expected, written = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize, 0
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                          "shape": tuple(int(n) for n in shape)}  # fmt: skip
                np.lib.format.write_array_header_1_0(fid, header)
                for part in parts():
                    data = np.ascontiguousarray(part, dtype=dtype).tobytes()
                    fid.write(data)
                    written += len(data)
            if written != expected:
                raise DataError(f"{path}: member {name} got {written} bytes of {expected}")
        for name, value in small.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, np.asanyarray(value), allow_pickle=False)
    return path
