"""One time base for a whole log: header stamps or record (receive) times, chosen and stated.

A recorded message has two times: the stamp its driver wrote (``header.stamp``: when the sensor
measured, on the driver's clock) and the time the recorder received it (the bag's record time).
Within one clock both are good; mixed, they are not: a replayed log re-recorded keeps its old
stamps on some topics and zero stamps on others, so stamps and record times differ by days. A
log is put on one clock:

- ``auto``: the header stamps when every stream has them (none zero or missing) and every
  stream's offset (record time - stamp, its median) agrees with the others' within
  ``tolerance_s`` (transport latency); else the record time for every stream;
- ``header``: the stamps; a message without one gets its record time minus the median offset
  of the streams that have stamps (put on the stamps' clock, stated);
- ``record``: the record time for every message.

:class:`ClockTable` collects both times per message (each row of a reader refers to its entry
by index); :func:`choose_time_base` makes the choice, :class:`TimeBase` states it in one line
and as a dict for every output's ``config.yaml``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError

POLICIES = ("auto", "header", "record")
#: default agreement of the streams' (record - stamp) offsets on one clock, s: transport and
#: driver latency (a DVL's report is stamped at its measurement, up to a few hundred ms before
#: it is received); offsets further apart are different clocks
CLOCK_TOLERANCE_S = 1.0


def check_policy(policy: str) -> str:
    word = str(policy).strip().lower()
    if word not in POLICIES:
        raise ConfigError(f"time base: expected auto, header or record, not {policy!r}")
    return word


class ClockTable:
    """Both times of every message read: ``add`` returns the message's index."""

    def __init__(self) -> None:
        self.stream: list[str] = []
        self.header: list[float] = []
        self.record: list[float] = []

    def add(self, stream: str, header_s: float, record_s: float) -> float:
        """Register a message (``header_s`` NaN when it has no stamp or a zero one); its index,
        as the float time placeholder of the reader's row."""
        self.stream.append(stream)
        self.header.append(header_s)
        self.record.append(record_s)
        return float(len(self.record) - 1)

    def __len__(self) -> int:
        return len(self.record)


@dataclass(frozen=True)
class TimeBase:
    """The chosen base and the evidence: per stream the messages without a stamp and the
    median offset record - stamp (s); ``shift_s``: what was subtracted from a stream's record
    times to put it on the stamps' clock (``header`` base only)."""

    base: str
    policy: str
    reason: str
    #: some stream lacks stamps or sits on another clock: the choice mattered (it is stated)
    mixed: bool = False
    missing_stamps: dict[str, int] = field(default_factory=dict)
    offsets_s: dict[str, float] = field(default_factory=dict)
    shift_s: dict[str, float] = field(default_factory=dict)
    times: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def line(self, source: str = "") -> str:
        what = "header stamps" if self.base == "header" else "record (receive) time"
        head = f"{source}: " if source else ""
        how = "chosen" if self.policy == "auto" else "as asked"
        return (
            f"{head}time base: {what} for every stream ({how}: {self.reason}); "
            "override with --time header|record"
        )

    def to_dict(self) -> dict:
        return {
            "base": self.base,
            "policy": self.policy,
            "reason": self.reason,
            "mixed_clocks": self.mixed,
            "missing_stamps": dict(self.missing_stamps),
            "offsets_s": {
                k: (None if math.isnan(v) else round(v, 6)) for k, v in self.offsets_s.items()
            },  # fmt: skip
            "shift_s": {k: round(v, 6) for k, v in self.shift_s.items()},
        }


def _fmt_offset(seconds: float) -> str:
    return f"{seconds:,.0f} s" if abs(seconds) >= 10 else f"{seconds:.3f} s"


def choose_time_base(
    table: ClockTable,
    policy: str = "auto",
    names: dict[str, str] | None = None,
    tolerance_s: float = CLOCK_TOLERANCE_S,
    streams: set[str] | None = None,
) -> TimeBase:
    """The time base of the messages of ``table`` (see the module docstring); ``names`` maps a
    stream to the topic shown in the reason, ``streams`` the ones that take part in the choice
    (default all). ``times`` of the result: the time of every message, by index."""
    policy = check_policy(policy)
    label = names or {}
    header = np.asarray(table.header, dtype=np.float64)
    record = np.asarray(table.record, dtype=np.float64)
    kinds = np.asarray(table.stream, dtype=object)
    present = sorted(set(table.stream))
    voting = [s for s in present if streams is None or s in streams]
    missing, offsets = {}, {}
    for s in present:
        sel = kinds == s
        have = np.isfinite(header[sel])
        missing[s] = int((~have).sum())
        diff = record[sel][have] - header[sel][have]
        offsets[s] = float(np.median(diff)) if diff.size else math.nan
    stamped = [s for s in voting if missing[s] == 0]
    unstamped = [s for s in voting if missing[s] > 0]
    finite = [offsets[s] for s in voting if math.isfinite(offsets[s])]
    spread = (max(finite) - min(finite)) if finite else 0.0
    common = float(np.median(finite)) if finite else math.nan

    def name(s: str) -> str:
        return label.get(s, s)

    if unstamped:
        partial = [f"{name(s)} ({missing[s]} of {int((kinds == s).sum())})" for s in unstamped]
        evidence = "messages without a header stamp on " + ", ".join(partial)
    elif spread > tolerance_s:
        far = max(voting, key=lambda s: abs(offsets[s] - common))
        others = [offsets[s] for s in voting if s != far and math.isfinite(offsets[s])]
        gap = offsets[far] - float(np.median(others)) if others else spread
        evidence = (
            f"the stamps of {name(far)} are {_fmt_offset(abs(gap))} off the other streams' "
            f"(offsets record - stamp spread over {_fmt_offset(spread)})"
        )
    else:
        evidence = ""
    if policy == "auto":
        base = "record" if evidence else "header"  # (evidence: stamps missing or clocks apart)
        if not evidence:
            n = len(stamped)
            evidence = (
                f"all {n} stream{'s' if n != 1 else ''} stamped, stamps "
                f"{_fmt_offset(common) if math.isfinite(common) else 'n/a'} before record time"
            )
        elif unstamped and stamped and math.isfinite(common) and abs(common) > tolerance_s:
            evidence += f"; the other streams' stamps are {_fmt_offset(common)} before record time"
    else:
        base = policy
        if not evidence:
            evidence = "the streams' stamps agree"
    times = record.copy()
    shift: dict[str, float] = {}
    if base == "header":
        have = np.isfinite(header)
        times[have] = header[have]
        for s in present:
            if missing[s]:
                offset = common if math.isfinite(common) else 0.0
                shift[s] = offset
                sel = (kinds == s) & ~have
                times[sel] = record[sel] - offset
    # mixed: some messages stamped and some not, or stamps on clocks apart (a log with no stamp
    # at all has one clock: the record time)
    any_stamp = any(missing[s] < int((kinds == s).sum()) for s in voting)
    mixed = (bool(unstamped) and any_stamp) or spread > tolerance_s
    return TimeBase(base, policy, evidence, mixed, missing, offsets, shift, times)
