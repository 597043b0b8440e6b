"""Records of ArduPilot dataflash logs (binary ``.BIN``, text ``.log``), framed robustly.

A binary log is a sequence of records [0xA3 0x95][type byte][body]; the body's layout is
declared by ``FMT`` records (type 0x80: Type, Length, Name, Format, Columns), each format
character a C type and, for ``c C e E L``, a fixed scale (centi-, 1e-7 degrees), as pymavlink's
:class:`pymavlink.DFReader.DFFormat` decodes them (``FORMAT_TO_STRUCT``). A text log has one
record a line, ``NAME, v1, v2, ...``, values already scaled. ``UNIT`` (id -> label), ``MULT``
(id -> multiplier) and ``FMTU`` (per format: one unit id and one multiplier id per column)
records say each field's unit (ArduPilot ``AP_Logger/LogStructure.h``).

The record layouts are pymavlink's (``DFFormat``); the framing loop is the one of
``DFReader_binary._parse_next`` with damage counted instead of printed: pymavlink's indexer
writes one line per damaged byte to the process's stderr and its Python fallback stops at the
first record of an unknown type. Here a damaged region (bytes that do not start a record of a
known format) is skipped to the next record header and counted once; after damage a record is
accepted only when the next record header follows it (or the data ends), so a header found by
chance inside garbage is not decoded. A record cut off by the end of the data is counted as
truncated. Bytes after the last record shorter than :data:`TRAILER_BYTES` are the padding
block-based loggers leave and are not damage (pymavlink ignores them too).
"""

from __future__ import annotations

import math
import re
import struct
from collections import Counter
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING

from .collect import MALFORMED

if TYPE_CHECKING:
    from pymavlink.DFReader import DFFormat


def _df():
    """pymavlink's ``DFReader`` module, imported at first use: it loads MAVLink dialects, which
    a live session must not import mid-dive (``undertow.live.links``' load-ahead test)."""
    from pymavlink import DFReader

    return DFReader


HEAD = b"\xa3\x95"
FMT_TYPE = 0x80
#: end-of-log padding of block loggers (pymavlink's DFReader ignores garbage in this span)
TRAILER_BYTES = 528
_FMT = ("FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
_TEXT_FMT = re.compile(rb"(?:^|\n)\s*FMT,")
#: formats whose characters carry their own scale (DFFormat applies it)
_SELF_SCALED = frozenset("cCeEL")
_STRING_CHARS = frozenset("nNZ")
_META = ("FMTU", "UNIT", "MULT")
#: the multipliers ArduPilot's MULT records define (AP_Logger/LogStructure.h: 0 for none,
#: powers of ten, 3.6 and 3600 for per-hour units); another value is a damaged record
MULTIPLIERS = frozenset([0.0, 3.6, 3600.0] + [float(f"1e{k}") for k in range(-9, 10)])


def looks_like_dataflash(head: bytes) -> str | None:
    """'binary' when ``head`` starts with a binary FMT record header (0xA3 0x95 0x80), 'text'
    when a line of it starts with ``FMT,`` (a text log), else None."""
    if head[:3] == HEAD + bytes([FMT_TYPE]):
        return "binary"
    if head.lstrip()[:1] not in (b"{", b"[") and _TEXT_FMT.search(head[:8000]):
        return "text"
    return None


class Scan:
    """What a scan found besides the wanted records: formats, unit tables, counts, damage."""

    def __init__(self) -> None:
        self.formats: dict[str, DFFormat] = {}  # by name (the last definition)
        self.unit_ids: dict[str, tuple[str, str]] = {}  # format name -> (UnitIds, MultIds)
        self.unit_lookup: dict[str, str] = {}
        self.mult_lookup: dict[str, float] = {}
        self.counts: Counter[str] = Counter()
        self.damaged = 0
        self.first_damage: int | None = None
        self.truncated = False
        self.trailing_bytes = 0
        self.bad_formats = 0
        self.bad_records = 0  # wanted records whose fields did not decode

    def damage(self, where: int) -> None:
        self.damaged += 1
        self.first_damage = where if self.first_damage is None else self.first_damage

    def unit(self, name: str, column: str) -> tuple[str, float] | None:
        """(unit label, multiplier still to apply) of ``name.column`` as the log's FMTU/UNIT/
        MULT records declare it; None when the log declares nothing for it. The multiplier is 1
        for columns whose format character carries its own scale (already applied) and for the
        ``-``/``0``/``?`` ids (none, 1, unknown)."""
        fmt = self.formats.get(name)
        ids = self.unit_ids.get(name)
        if fmt is None or ids is None or column not in fmt.colhash:
            return None
        i = fmt.colhash[column]
        unit_ids, mult_ids = ids
        label = self.unit_lookup.get(unit_ids[i], "") if i < len(unit_ids) else ""
        mult = self.mult_lookup.get(mult_ids[i], 0.0) if i < len(mult_ids) else 0.0
        if fmt.format[i] in _SELF_SCALED or not math.isfinite(mult) or mult <= 0.0:
            mult = 1.0
        return label, float(mult)


def new_format(ftype, length, name, form, columns) -> DFFormat:
    """A DFFormat from an FMT record's Type, Length, Name, Format and Columns; ValueError when
    a format character is unknown (checked first: DFFormat prints before it raises), the
    columns do not match the format characters one to one, or, in a binary log (``length``
    not None), the length is not the body's size plus the header's 3."""
    name, form, columns = _df().null_term(name), _df().null_term(form), _df().null_term(columns)
    unknown = sorted(set(form) - set(_df().FORMAT_TO_STRUCT))
    if unknown or not name or not form:
        raise ValueError(f"FMT {name!r}: format {form!r} empty or with unknown characters")
    fmt = _df().DFFormat(int(ftype), name, -1 if length is None else int(length), form, columns)
    if len(fmt.columns) != len(fmt.format):
        raise ValueError(f"FMT {name!r}: {len(fmt.columns)} columns for format {form!r}")
    if length is not None and struct.calcsize(fmt.msg_struct) + 3 != fmt.len:
        raise ValueError(f"FMT {fmt.name!r}: length {fmt.len} does not match {fmt.format!r}")
    return fmt


class BinaryScanner:
    """Walks a binary dataflash log; :meth:`records` yields (format, raw elements) of the
    records named in ``wanted`` (fields unpacked, format scales not yet applied)."""

    def __init__(self, data: bytes, wanted: Iterable[str]) -> None:
        self.data = data
        self.wanted = frozenset(wanted)
        self.scan = Scan()
        fmt = _df().DFFormat(FMT_TYPE, *_FMT[:1], 89, *_FMT[1:])
        self._types: dict[int, DFFormat] = {FMT_TYPE: fmt}
        self._structs: dict[int, struct.Struct] = {FMT_TYPE: struct.Struct(fmt.msg_struct)}

    def _starts(self, i: int) -> DFFormat | None:
        data = self.data
        if data[i : i + 2] != HEAD or i + 3 > len(data):
            return None
        return self._types.get(data[i + 2])

    def _confirmed(self, end: int) -> bool:
        """True when a record header of a known type starts at ``end`` or the data ends."""
        return end >= len(self.data) or self._starts(end) is not None

    def records(self) -> Iterator[tuple[DFFormat, tuple]]:
        data, scan, n = self.data, self.scan, len(self.data)
        i, damage_at = 0, -1  # damage_at: start of the damaged region being skipped, or -1
        while i + 3 <= n:
            fmt = self._starts(i)
            if fmt is not None and damage_at < 0 and i + fmt.len > n:
                scan.truncated = True
                break
            if fmt is None or (damage_at >= 0 and not self._confirmed(i + fmt.len)):
                damage_at = i if damage_at < 0 else damage_at
                nxt = data.find(HEAD, i + 1)
                i = n if nxt < 0 else nxt
                continue
            if damage_at >= 0:
                scan.damage(damage_at)
                damage_at = -1
            body = self._structs[fmt.type].unpack_from(data, i + 3)
            i += fmt.len
            name = fmt.name
            scan.counts[name] += 1
            if fmt.type == FMT_TYPE:
                self._define(body)
            elif name in _META:
                self._meta(fmt, body)
            elif name in self.wanted:
                yield fmt, body
        if damage_at >= 0 and n - damage_at >= TRAILER_BYTES:
            scan.damage(damage_at)
        elif damage_at >= 0 or (i < n and not scan.truncated):
            scan.trailing_bytes = n - (damage_at if damage_at >= 0 else i)

    def _define(self, body) -> None:
        try:
            fmt = new_format(*body)
        except MALFORMED:
            self.scan.bad_formats += 1
            return
        if _redefines(self._types.get(fmt.type), fmt):
            self.scan.bad_formats += 1
            return
        self._types[fmt.type] = fmt
        self._structs[fmt.type] = struct.Struct(fmt.msg_struct)
        self.scan.formats[fmt.name] = fmt

    def _meta(self, fmt: DFFormat, body) -> None:
        try:
            _store_meta(self.scan, fmt, body, self._types)
        except MALFORMED:
            self.scan.bad_records += 1


def _redefines(old: DFFormat | None, new: DFFormat) -> bool:
    """True when ``new`` gives a defined type (or name) another layout: ArduPilot never does
    within a log (it may repeat an FMT, and FMT describes itself), so it is a damaged record."""
    if old is None:
        return False
    return (old.type, old.name, old.format, old.columns) != (
        new.type,
        new.name,
        new.format,
        new.columns,
    )


def _store_meta(scan: Scan, fmt: DFFormat, body, types: dict) -> None:
    """Keep a UNIT (Id -> Label), MULT (Id -> Mult) or FMTU (FmtType -> UnitIds, MultIds)."""
    col = fmt.colhash
    if fmt.name == "UNIT":
        scan.unit_lookup[_id_char(body[col["Id"]])] = _text(body[col["Label"]])
    elif fmt.name == "MULT":
        mult = float(f"{float(body[col['Mult']]):.7g}")  # (float32 values, as pymavlink rounds)
        if mult not in MULTIPLIERS:
            raise ValueError(f"MULT {mult}: not one of ArduPilot's multipliers")
        scan.mult_lookup[_id_char(body[col["Id"]])] = mult
    else:
        target = types.get(int(body[col["FmtType"]]))
        if target is not None:
            ids = (_text(body[col["UnitIds"]]), _text(body[col["MultIds"]]))
            scan.unit_ids[target.name] = ids


def _id_char(value) -> str:
    """A UNIT/MULT id: an int8 in binary logs, a number or the character itself in text."""
    if isinstance(value, str) and not value.lstrip("-").isdigit():
        return value[:1]
    return chr(int(value) & 0xFF)


def _text(value) -> str:
    return _df().null_term(value) if isinstance(value, bytes | str) else str(value)


class TextScanner:
    """Walks a text dataflash log (``NAME, v1, v2, ...`` per line, the FMT lines first);
    :meth:`records` yields (format, element strings) of the records named in ``wanted``."""

    def __init__(self, text: str, wanted: Iterable[str]) -> None:
        self.lines = text.splitlines()
        self.wanted = frozenset(wanted)
        self.scan = Scan()
        self._by_type: dict[int, DFFormat] = {}

    def records(self) -> Iterator[tuple[DFFormat, tuple]]:
        scan = self.scan
        for number, line in enumerate(self.lines, 1):
            parts = [p.strip() for p in line.split(",")]
            name = parts[0]
            if not name:
                continue
            if name == "FMT":
                self._define(parts)
                continue
            fmt = scan.formats.get(name)
            width = len(fmt.format) if fmt is not None else 0
            if fmt is None or len(parts) - 1 < width:
                scan.damage(number)  # (a line of an undefined format, or cut short)
                continue
            values = parts[1 : width + 1]
            if len(parts) - 1 > width and fmt.format[-1] in _STRING_CHARS:
                values[-1] = ",".join(parts[width:])  # a string field holding commas
            scan.counts[name] += 1
            if name in _META:
                try:
                    _store_meta(scan, fmt, values, self._by_type)
                except MALFORMED:
                    scan.bad_records += 1
            elif name in self.wanted:
                yield fmt, tuple(values)

    def _define(self, parts: list[str]) -> None:
        self.scan.counts["FMT"] += 1
        if len(parts) < 6:
            self.scan.bad_formats += 1
            return
        try:
            fmt = new_format(parts[1], None, parts[3], parts[4], ",".join(parts[5:]))
        except MALFORMED:
            self.scan.bad_formats += 1
            return
        if _redefines(self.scan.formats.get(fmt.name), fmt) or _redefines(
            self._by_type.get(fmt.type), fmt
        ):
            self.scan.bad_formats += 1
            return
        self.scan.formats[fmt.name] = fmt
        self._by_type[fmt.type] = fmt


class Columns:
    """Extracts named columns of one format as floats (format scales applied as pymavlink's
    DFMessage does; text values are already scaled). A column the format lacks gives NaN."""

    def __init__(self, fmt: DFFormat, names: tuple[str, ...], text: bool) -> None:
        self.index = [fmt.colhash.get(n) for n in names]
        scale = [None if text or i is None else fmt.msg_mults[i] for i in self.index]
        self.divisor = [1.0 / m if m and 0.0 < m < 1.0 else None for m in scale]
        self.factor = [m if m and m >= 1.0 else None for m in scale]

    def __call__(self, elements) -> tuple[float, ...]:
        out = []
        for i, div, mul in zip(self.index, self.divisor, self.factor, strict=True):
            if i is None:
                out.append(math.nan)
                continue
            v = float(elements[i])  # (bytes or a bad string: ValueError/TypeError)
            out.append(v / div if div else v * mul if mul else v)  # (as DFMessage: / 1e7)
        return tuple(out)


def text_field(fmt: DFFormat, elements, name: str) -> str:
    """A string column of a record ('' when the format has none)."""
    i = fmt.colhash.get(name)
    return "" if i is None else _text(elements[i])
