"""Peer estimators: the field's strongest systems beside the paper's UKF, on the same sensors and
noise (:mod:`undertow.peers.inputs`), each a function ``Log -> Trajectory``.

``ESTIMATORS`` maps a name to ``"module:function"`` (resolved at first use, so that the optional
dependencies, e.g. gtsam for the factor graph, load only when asked); ``"ukf"`` is the paper's
filter (:func:`undertow.estimation.localize`), kept as None here:

- ``factor-graph``: GTSAM batch smoother, Levenberg-Marquardt (:mod:`.factor_graph`);
- ``isam2``: the same graph solved incrementally, each state's estimate taken online;
- ``inekf``: an invariant EKF on SE_2(3) (:mod:`.inekf`).

``run_estimator(name, log, **kw)`` runs one of them by name (``ukf``: localize).
"""

from __future__ import annotations

import importlib

from ..errors import ConfigError
from ..log import Log
from ..trajectory import Trajectory

ESTIMATORS: dict[str, str | None] = {
    "ukf": None,
    "factor-graph": "undertow.peers.factor_graph:factor_graph",
    "isam2": "undertow.peers.factor_graph:isam2",
    "inekf": "undertow.peers.inekf:inekf",
}
UKF = "ukf"


def resolve(name: str):
    """The function of the estimator ``name`` (ConfigError: unknown name, or its module or
    optional dependency missing, one line)."""
    if name not in ESTIMATORS:
        raise ConfigError(f"estimator {name!r}: unknown (use {', '.join(ESTIMATORS)})")
    target = ESTIMATORS[name]
    if target is None:
        from ..estimation.localizer import localize

        return localize
    module_name, _, attr = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError(f"estimator {name!r} is not available: {exc}") from None
    return getattr(module, attr)


def run_estimator(name: str, log: Log, **kw) -> Trajectory:
    """``name``'s trajectory of ``log``; ``kw`` as :func:`undertow.peers.inputs.peer_inputs` takes
    them (profile, wave, calibration, extrapolate, LocalizerConfig fields), plus the estimator's
    own options."""
    return resolve(name)(log, **kw)


__all__ = ["ESTIMATORS", "UKF", "resolve", "run_estimator"]
