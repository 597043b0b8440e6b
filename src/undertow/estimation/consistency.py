"""The filter's own honesty on data with no truth: how its innovations compare with what it
expected of them.

For a consistent filter (right model, right noise) the innovation nu_k = z_k - h(x_k^-) of
every measurement is zero-mean with the covariance S_k the filter computes, and white: unrelated
to the one before (Bar-Shalom, Li and Kirubarajan, "Estimation with Applications to Tracking and
Navigation", Wiley 2001, sec. 5.4.2; Mehra, "On the identification of variances and adaptive
Kalman filtering", IEEE TAC 1970). The filter loop records for each measurement its whitened
innovation w_k = L_k^-1 nu_k (S_k = L_k L_k^T, :func:`~undertow.estimation.filter_loop.run_filter`),
so that NIS_k = nu_k^T S_k^-1 nu_k = w_k^T w_k ~ chi2(m), m = dim z. Per sensor kind, over its K
evaluated innovations (applied or gated):

- mean NIS, expected m. Under H0, K mean ~ chi2(K m) (the time-average NIS test of
  Bar-Shalom et al. 2001, sec. 5.4.2), so the two-sided 95 % band of the mean is
  [chi2_0.025(K' m), chi2_0.975(K' m)] / K'. Consecutive innovations of a real filter are
  rarely independent, and a correlated series has fewer independent samples than K:
  K' = K (1 - r) / (1 + r), with r the lag-1 autocorrelation of the NIS series (centred)
  clipped to [0, 0.99] (the effective sample size of an AR(1) series, Bretherton et al., "The
  effective number of spatial degrees of freedom of a time-varying field", J. Climate 12, 1999,
  eq. 31). Mean above the band: ``overconfident`` (the innovations are larger than the filter
  expects: a noise understated, or a model error); below: ``pessimistic`` (a noise overstated:
  the filter ignores information it has);
- the share of NIS_k outside the per-sample two-sided 95 % interval [chi2_0.025(m),
  chi2_0.975(m)], expected 5 % (2.5 % below, 2.5 % above; both sides reported), as expected
  when within 0.05 +- 1.96 sqrt(0.05 0.95 / K') (the normal approximation of the binomial): a
  mean NIS in its band with a share far from 5 % is a distribution of the wrong shape (e.g. the
  motion model right on average but wrong in the manoeuvres: tiny innovations at cruise, huge
  ones in the turns);
- whiteness: the time-average lag-1 autocorrelation of the whitened innovations (the single-run
  whiteness test of Bar-Shalom et al. 2001, sec. 5.4.2, on the normalized innovations)

      rho_1 = sum_k w_k^T w_{k+1} / sqrt(sum_k w_k^T w_k  sum_k w_{k+1}^T w_{k+1}),

  about N(0, 1 / ((K - 1) m)) under H0 (the m products of each term are independent with
  variance 1), so |rho_1| above 1.96 / sqrt((K - 1) m) says the innovations are correlated (the
  motion model misses something the sensor sees, or a bias is not modelled).

With thousands of innovations the statistical bands become narrower than anything a noise
setting means, and every real run would fail them. The verdicts therefore also accept a mean NIS
within ``NIS_TOLERANCE`` (10 %) of m (NIS scales as 1 / sigma^2: 10 % is a 5 % error in a
standard deviation), a share outside within ``SHARE_TOLERANCE`` (2 points) of 5 %, and
|rho_1| up to ``WHITE_TOLERANCE`` (0.1: an AR(1) correlation of 0.1 widens the variance of a
mean by (1 + rho) / (1 - rho) = 1.22 at most); the statistical bands are reported as they are.

Quantiles are scipy.special.chdtri's (the inverse chi-square survival function).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from . import model

PROBABILITY = 0.95  # the bands' coverage
Z_95 = 1.959963984540054  # the standard normal's two-sided 95 % quantile
MAX_NIS_CORRELATION = 0.99  # r is clipped below this in K' (a constant series has K' ~ K / 200)
NIS_TOLERANCE = 0.1  # a mean NIS within 10 % of dim z is consistent whatever its band
SHARE_TOLERANCE = 0.02  # a share outside within 2 points of 5 % is as expected
WHITE_TOLERANCE = 0.1  # |rho_1| up to 0.1 is white whatever its band
CONSISTENT, OVERCONFIDENT, PESSIMISTIC, NONE = (
    "consistent",
    "overconfident",
    "pessimistic",
    "no innovations",
)
MEANING = {
    CONSISTENT: "innovations as large as the filter expects",
    OVERCONFIDENT: "innovations larger than the filter expects: a noise understated (or a model "
    "error)",
    PESSIMISTIC: "innovations smaller than the filter expects: a noise overstated",
    NONE: "no innovation evaluated",
}
#: the verdicts as the one-line summary and the table print them
LABELS = {CONSISTENT: "ok", OVERCONFIDENT: "too large", PESSIMISTIC: "too small"}


@dataclass(frozen=True)
class SensorConsistency:
    """One sensor kind's innovations: NIS mean against its 95 % band (``nis_band_low``,
    ``nis_band_high``, over ``effective_count`` independent samples), the share outside the
    per-sample 95 % interval (expected 0.05; ``share_as_expected``), the lag-1
    autocorrelation of the whitened innovations against +-``autocorrelation_band``, and the
    verdict (module doc). Numbers are None without innovations (and the autocorrelation with
    fewer than 3)."""

    sensor: str
    dof: int
    count: int
    verdict: str
    nis_mean: float | None = None
    nis_band_low: float | None = None
    nis_band_high: float | None = None
    effective_count: float | None = None
    share_outside: float | None = None
    share_below: float | None = None
    share_above: float | None = None
    expected_share_outside: float = 1.0 - PROBABILITY
    share_as_expected: bool | None = None
    autocorrelation_lag1: float | None = None
    autocorrelation_band: float | None = None
    white: bool | None = None

    @property
    def consistent(self) -> bool:
        return self.verdict == CONSISTENT


@dataclass(frozen=True)
class ConsistencyReport:
    """The innovations' consistency per sensor kind (:func:`innovation_consistency`)."""

    sensors: tuple[SensorConsistency, ...]
    probability: float = PROBABILITY

    def to_dict(self) -> dict:
        return {
            "probability": self.probability,
            "sensors": {s.sensor: _rounded(asdict(s)) for s in self.sensors},
        }

    @classmethod
    def from_dict(cls, data: dict) -> ConsistencyReport:
        """The report written by :meth:`to_dict` (e.g. a trajectory's ``metadata``)."""
        sensors = tuple(
            SensorConsistency(**{**fields, "sensor": name})
            for name, fields in data["sensors"].items()
        )
        return cls(sensors, float(data.get("probability", PROBABILITY)))

    @property
    def evaluated(self) -> tuple[SensorConsistency, ...]:
        """The sensors with at least one innovation."""
        return tuple(s for s in self.sensors if s.count)

    def summary(self) -> str:
        """One line: each sensor's mean NIS over its expected value and verdict, with the share
        outside when it is not about 5 % and "correlated" when the innovations are not white."""
        parts = []
        for s in self.evaluated:
            notes = []
            if s.share_as_expected is False:
                notes.append(f"{100 * s.share_outside:.0f} % outside")
            if s.white is False:
                notes.append("correlated")
            note = f" ({', '.join(notes)})" if notes else ""
            parts.append(f"{s.sensor} {s.nis_mean:.3g}/{s.dof} {_short(s.verdict)}{note}")
        return "NIS mean/expected: " + (", ".join(parts) or "no innovations")


def _short(verdict: str) -> str:
    return LABELS.get(verdict, verdict)


def _rounded(fields: dict) -> dict:
    """Floats to 6 significant digits (a report read by people and diffed in config.yaml)."""
    return {k: float(f"{v:.6g}") if isinstance(v, float) else v for k, v in fields.items()}


def innovation_consistency(kind: np.ndarray, whitened: np.ndarray) -> ConsistencyReport:
    """The report of a run's innovations: ``kind`` (N,) the rows' sensor kinds
    (:data:`~undertow.estimation.model.KIND_NAMES` order), ``whitened`` (N, 3) their whitened
    innovations in time order (the first KIND_DIM[kind] entries used; NaN: none evaluated)."""
    kind = np.asarray(kind)
    whitened = np.asarray(whitened, float)
    sensors = []
    for k, name in enumerate(model.KIND_NAMES):
        m = model.KIND_DIM[k]
        w = whitened[kind == k, :m]
        sensors.append(sensor_consistency(name, w[np.isfinite(w).all(axis=1)]))
    return ConsistencyReport(tuple(sensors))


def sensor_consistency(sensor: str, w: np.ndarray) -> SensorConsistency:
    """One sensor's consistency from its whitened innovations ``w`` (K, m), in time order."""
    K, m = w.shape
    if K == 0:
        return SensorConsistency(sensor, m, 0, NONE)
    from scipy.special import chdtri  # 0.1 s to import: only when a report is made

    nis = np.einsum("ka,ka->k", w, w)
    mean = float(nis.mean())
    r = _lag1(nis[:, None] - mean) if K >= 3 else None
    clipped = min(max(r or 0.0, 0.0), MAX_NIS_CORRELATION)
    k_eff = K * (1.0 - clipped) / (1.0 + clipped)
    tail = (1.0 - PROBABILITY) / 2
    low, high = (float(chdtri(k_eff * m, q)) / k_eff for q in (1.0 - tail, tail))
    below, above = float(chdtri(m, 1.0 - tail)), float(chdtri(m, tail))
    share_below, share_above = float(np.mean(nis < below)), float(np.mean(nis > above))
    expected = 1.0 - PROBABILITY
    share_tolerance = Z_95 * math.sqrt(expected * (1.0 - expected) / k_eff)
    rho = _lag1(w) if K >= 3 else None
    band = Z_95 / math.sqrt((K - 1) * m) if K >= 3 else None
    upper, lower = max(high, (1 + NIS_TOLERANCE) * m), min(low, (1 - NIS_TOLERANCE) * m)
    verdict = OVERCONFIDENT if mean > upper else PESSIMISTIC if mean < lower else CONSISTENT
    share_tolerance = max(share_tolerance, SHARE_TOLERANCE)
    return SensorConsistency(
        sensor=sensor,
        dof=m,
        count=int(K),
        verdict=verdict,
        nis_mean=mean,
        nis_band_low=low,
        nis_band_high=high,
        effective_count=float(k_eff),
        share_outside=share_below + share_above,
        share_below=share_below,
        share_above=share_above,
        share_as_expected=bool(abs(share_below + share_above - expected) <= share_tolerance),
        autocorrelation_lag1=rho,
        autocorrelation_band=band,
        white=None if rho is None else bool(abs(rho) <= max(band, WHITE_TOLERANCE)),
    )


def _lag1(w: np.ndarray) -> float | None:
    """rho_1 = sum_k w_k . w_{k+1} / sqrt(sum_k |w_k|^2 sum_k |w_{k+1}|^2) over the rows of w,
    as given (the whitened innovations are not centred: a mean offset shows as correlation, as
    it should); None for a series without energy."""
    a, b = w[:-1], w[1:]
    energy = float(np.sum(a * a)) * float(np.sum(b * b))
    if not energy > 0:
        return None
    return float(np.sum(a * b) / math.sqrt(energy))
