"""PLY point clouds (readable by CloudCompare, Open3D, Foxglove).

:func:`write_ply` writes vertices as float32 ``x y z`` plus one float32 property per named
array (e.g. occupancy probability), binary little-endian by default or ASCII; atomic.
:func:`write_map_ply` writes an occupancy map's occupied cells that way.
:func:`read_ply` reads the ``vertex`` element of ``ascii`` and ``binary_little_endian`` files
(any scalar property types; elements before ``vertex`` must have no list properties). Any
malformed header or body is one :class:`~undertow.errors.ReaderError` line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util.atomic import atomic_path, atomic_write_text
from ..errors import DataError, ReaderError
from ..occupancy import OCCUPIED_THRESHOLD, OccupancyMap
from .collect import MALFORMED, read_regular_bytes

_TYPES = {
    "char": "i1",
    "uchar": "u1",
    "short": "<i2",
    "ushort": "<u2",
    "int": "<i4",
    "uint": "<u4",
    "float": "<f4",
    "double": "<f8",
    "int8": "i1",
    "uint8": "u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "float32": "<f4",
    "float64": "<f8",
}


def write_ply(path, points, properties: dict | None = None, binary: bool = True) -> Path:
    """Write (N,3) ``points`` and optional (N,) ``properties`` as a PLY file."""
    path = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DataError(f"write_ply {path}: points must be (N, 3), got {pts.shape}")
    n = pts.shape[0]
    props = {k: np.asarray(v, dtype=np.float32).reshape(-1) for k, v in (properties or {}).items()}
    for name, arr in props.items():
        if arr.size != n or not name.isidentifier():
            raise DataError(f"write_ply {path}: property {name!r} must be a name with {n} values")
    names = ["x", "y", "z", *props]
    dtype = np.dtype([(name, "<f4") for name in names])
    table = np.empty(n, dtype=dtype)
    for i, axis in enumerate("xyz"):
        table[axis] = pts[:, i]
    for name, arr in props.items():
        table[name] = arr
    header = _header(n, names, "binary_little_endian" if binary else "ascii")
    if binary:
        with atomic_path(path) as tmp:
            tmp.write_bytes(header.encode("ascii") + table.tobytes())
    else:
        body = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in table.tolist())
        atomic_write_text(path, header + body)
    return path


def _header(n: int, names, fmt: str) -> str:
    return (
        f"ply\nformat {fmt} 1.0\ncomment written by undertow\nelement vertex {n}\n"
        + "".join(f"property float {name}\n" for name in names)
        + "end_header\n"
    )


def write_ply_parts(path, n: int, names: list[str], parts) -> Path:
    """A binary PLY of ``n`` vertices with float properties x, y, z, ``names`` written part by
    part (the bytes :func:`write_ply` writes for the parts joined): ``parts`` yields (points
    (k, 3), {name: (k,)}); atomic. The parts must hold ``n`` vertices in all."""
    path = Path(path)
    dtype = np.dtype([(name, "<f4") for name in ["x", "y", "z", *names]])
    written = 0
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(_header(n, ["x", "y", "z", *names], "binary_little_endian").encode("ascii"))
        for points, props in parts:
            table = np.empty(len(points), dtype=dtype)
            for i, axis in enumerate("xyz"):
                table[axis] = np.asarray(points, np.float64)[:, i]
            for name in names:
                table[name] = np.asarray(props[name], dtype=np.float32).reshape(-1)
            fh.write(table.tobytes())
            written += len(points)
        if written != n:
            raise DataError(f"write_ply {path}: {written} vertices written, {n} announced")
    return path


def write_map_ply(path, occupancy_map: OccupancyMap, threshold: float = OCCUPIED_THRESHOLD) -> Path:
    """Occupied cell centres (mean occupancy > ``threshold``) with float ``mean`` and
    ``variance`` vertex properties, as a binary little-endian PLY (CloudCompare, Open3D)."""
    occ = occupancy_map.occupied(threshold)
    return write_ply(path, occ.centres, {"mean": occ.mean, "variance": occ.variance})


def _parse_header(path: Path, data: bytes):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0 or data.find(b"\n", end) < 0:
        raise ReaderError(f"{path}: not a PLY file (no 'ply' magic or no end_header line)")
    body_start = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for number, line in enumerate(data[:end].decode("ascii", "replace").splitlines(), start=1):
        words = line.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        if words[0] == "format":
            fmt = words[1] if len(words) > 1 else None
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise ReaderError(f"{path}: header line {number}: malformed element {line!r}")
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if len(words) < 3:
                raise ReaderError(f"{path}: header line {number}: malformed property {line!r}")
            if words[1] == "list":
                elements[-1][2].append((words[-1], None))
            elif words[1] in _TYPES:
                elements[-1][2].append((words[2], _TYPES[words[1]]))
            else:
                raise ReaderError(f"{path}: header line {number}: unknown type {words[1]!r}")
    if fmt not in ("ascii", "binary_little_endian"):
        raise ReaderError(f"{path}: unsupported PLY format {fmt!r}")
    return fmt, elements, body_start


def read_ply(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(points (N,3) float64, {property: (N,) array}) of the vertex element of a PLY file."""
    path = Path(path)
    data = read_regular_bytes(path)
    try:
        return _read_ply(path, data)
    except (*MALFORMED, MemoryError) as exc:
        first = (str(exc).splitlines() or [""])[0][:200]
        raise ReaderError(f"{path}: malformed PLY file ({type(exc).__name__}: {first})") from None


def _read_ply(path: Path, data: bytes) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    fmt, elements, offset = _parse_header(path, data)
    skip_rows = 0
    for name, count, props in elements:
        if name == "vertex":
            break
        if any(t is None for _, t in props):
            raise ReaderError(f"{path}: element {name!r} with list properties before vertex")
        skip_rows += count
        offset += count * np.dtype([(p, t) for p, t in props]).itemsize
    else:
        raise ReaderError(f"{path}: no vertex element")
    if any(t is None for _, t in props) or not {"x", "y", "z"} <= {p for p, _ in props}:
        raise ReaderError(f"{path}: vertex element needs scalar x, y, z properties")
    dtype = np.dtype([(p, t) for p, t in props])
    try:
        if count == 0:  # a valid, empty cloud (e.g. a map with no occupied cell)
            table = np.empty(0, dtype=dtype)
        elif fmt == "binary_little_endian":
            table = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
        else:
            lines = data[offset:].decode("ascii").splitlines()[skip_rows : skip_rows + count]
            values = np.array([line.split() for line in lines], dtype=np.float64)
            table = np.empty(count, dtype=dtype)
            for i, (p, _) in enumerate(props):
                table[p] = values[:, i]
    except (ValueError, IndexError) as exc:
        raise ReaderError(f"{path}: truncated or malformed vertex data ({exc})") from exc
    points = np.column_stack([table[a].astype(np.float64) for a in "xyz"]).reshape(-1, 3)
    extra = {p: np.array(table[p]) for p, _ in props if p not in ("x", "y", "z")}
    return points, extra
