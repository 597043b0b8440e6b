"""The IHO S-44 survey orders a surface's depth uncertainty is held to.

IHO S-44, "Standards for Hydrographic Surveys", 6th ed. 2020, Table 1, bounds a depth's total
vertical uncertainty at the 95 % confidence level by

    TVU_max(d) = sqrt(a^2 + (b d)^2),

d the depth (m) and (a, b) the order's constants (:data:`IHO_ORDERS`). A depth of standard
deviation s (a normal error) has its 95 % uncertainty at z_95 s, z_95 = 1.96 (the two-sided
95 % quantile of the normal), so a column meets the order when

    z_95 s <= TVU_max(d).

Hydrographic software reports this per node as the uncertainty's ratio to the allowed TVU
(e.g. QPS Qimera's and Teledyne CARIS's "IHO S-44 compliance" layers); a depth that fails it
does not meet the survey's standard. :func:`meets_order` is that test.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError

#: (a m, b) of the total vertical uncertainty of each order (S-44 6th ed. 2020, Table 1)
IHO_ORDERS = {
    "exclusive": (0.15, 0.0075),
    "special": (0.25, 0.0075),
    "1a": (0.5, 0.013),
    "1b": (0.5, 0.013),
    "2": (1.0, 0.023),
}
#: no order: every column with data is kept
NO_ORDER = "none"
#: the order a tpu map's surface is held to unless told otherwise: Order 1a, S-44's order for
#: waters where features may exist but under-keel clearance is less critical (the general one)
DEFAULT_IHO_ORDER = "1a"
#: the two-sided 95 % quantile of the normal distribution
Z95 = 1.959963984540054


def withheld_notes(order: str, withheld: int) -> list[str]:
    """The line saying what holding a surface to ``order`` left out (none when nothing was)."""
    if not withheld:
        return []
    return [f"IHO S-44 order {order}: {withheld} columns withheld, their 95 % depth "
            "uncertainty above the order's TVU (--iho-order none keeps them)"]  # fmt: skip


def check_order(order: str) -> str:
    """``order`` checked: one of :data:`IHO_ORDERS` or :data:`NO_ORDER` (case-insensitive)."""
    name = str(order).strip().lower()
    if name not in (*IHO_ORDERS, NO_ORDER):
        raise ConfigError(
            f"IHO order {order!r}: expected one of {', '.join((*IHO_ORDERS, NO_ORDER))}"
        )
    return name


def allowed_tvu(depth, order: str) -> np.ndarray:
    """TVU_max(d) = sqrt(a^2 + (b d)^2) (m, 95 %) of ``order`` at depths ``depth`` (m; the
    magnitude is used, so a z-up depth gives the same)."""
    a, b = IHO_ORDERS[check_order(order)]
    return np.hypot(a, b * np.abs(np.asarray(depth, dtype=float)))


def meets_order(depth, std, order: str) -> np.ndarray:
    """Whether each depth of standard deviation ``std`` meets ``order``: z_95 s <= TVU_max(d)
    (module doc); False where either is not finite; all True for :data:`NO_ORDER`."""
    depth, std = np.broadcast_arrays(np.asarray(depth, float), np.asarray(std, float))
    if check_order(order) == NO_ORDER:
        return np.ones(depth.shape, bool)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & np.isfinite(std) & (Z95 * std <= allowed_tvu(depth, order))
