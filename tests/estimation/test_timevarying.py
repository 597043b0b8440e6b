"""Wave noise that follows the sea: gamma per measurement row from a WaveTrack (time-varying R).

Expected values come from the paper's Table I (the shipped profile) and closed-form linear
interpolation in time; a constant condition in any form must give the same trajectory as the
scalar condition, bit for bit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from undertow import seastate
from undertow.errors import ConfigError
from undertow.estimation import localize
from undertow.estimation.config import LocalizerConfig
from undertow.estimation.localizer import WAVE_ESTIMATED
from undertow.estimation.model import DR, DVL
from undertow.estimation.noise import NoiseProfile
from undertow.estimation.rows import measurements
from undertow.evaluation.trajectory import trajectory_rmse
from undertow.wavetrack import WaveTrack

TABLE_I_A10_F100 = np.array([0.025, 0.010, 0.003])  # the paper's Table I, wave-a0.10-f1.00
TABLE_I_A05_F075 = np.array([0.011, 0.010, 0.003])


@pytest.fixture(scope="module")
def wave_log(simulation):
    return simulation("wave-a0.10-f1.00", 0).log


def _same(a, b) -> bool:
    return np.array_equal(a.t, b.t) and np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)


@pytest.mark.parametrize("variant", ["an", "proposed"])
def test_a_constant_condition_in_any_form_is_bit_identical(wave_log, variant):
    ref = localize(wave_log, variant)  # the log's scalar {"amplitude_m", "frequency_hz"}
    assert ref.metadata["wave_condition"] == "wave-a0.10-f1.00"
    nodes = WaveTrack(np.array([0.0, 10.0, 40.0]), np.full(3, 0.1), np.full(3, 1.0), "estimated")
    as_track = {"source": "scenario", "t": [0.0, 30.0], "amplitude_m": [0.1, 0.1],
                "frequency_hz": [1.0, 1.0]}  # fmt: skip
    forms = {
        "name": dict(wave="wave-a0.10-f1.00"),
        "constant track": dict(wave=WaveTrack.constant(0.1, 1.0)),
        "three equal nodes": dict(wave=nodes),
    }
    for name, kwargs in forms.items():
        run = localize(wave_log, variant, **kwargs)
        assert _same(run, ref), name
        assert run.metadata["wave_noise"] == ref.metadata["wave_noise"], name
        assert "wave_track" not in run.metadata
    logged = localize(wave_log.replace(metadata={**wave_log.metadata, "wave": as_track}), variant)
    assert _same(logged, ref)
    assert logged.metadata["wave_condition_source"] == ref.metadata["wave_condition_source"]


def test_each_rows_gamma_is_interpolated_in_time_and_held_outside(wave_log):
    """Calm at t = 10 s, wave-a0.10-f1.00 at t = 30 s: a DVL row at t adds
    (w(t) gamma_Table_I)^2 with w = 0 before 10 s, (t - 10) / 20 between, 1 after 30 s."""
    cfg = LocalizerConfig(variant="proposed")
    track = WaveTrack(np.array([10.0, 30.0]), np.array([0.0, 0.1]), np.array([np.nan, 1.0]))
    noise = NoiseProfile.paper().noise_track(track)
    calm = NoiseProfile.paper().noise("calm")
    with_waves, _ = measurements(wave_log, cfg, noise)
    without, _ = measurements(wave_log, cfg, calm)
    dvl = with_waves["kind"] == DVL
    t = with_waves["t"][dvl]
    extra = np.diagonal(with_waves["R"][dvl] - without["R"][dvl], axis1=1, axis2=2)
    w = np.clip((t - 10.0) / 20.0, 0.0, 1.0)
    np.testing.assert_allclose(extra, (w[:, None] * TABLE_I_A10_F100) ** 2, atol=1e-15)
    assert np.any(t < 10) and np.any(t > 30)  # both held ends are exercised
    dr = with_waves["kind"] == DR  # Table I has no DR column: gamma_DR = 0 throughout
    np.testing.assert_array_equal(with_waves["R"][dr], without["R"][dr])


def test_time_varying_metadata_and_effect(wave_log):
    track = WaveTrack(np.array([0.0, 20.0, 40.0]), np.array([0.0, 0.1, 0.05]),
                      np.array([np.nan, 1.0, 0.75]), "scenario")  # fmt: skip
    run = localize(wave_log, "proposed", wave=track)
    meta = run.metadata
    assert meta["wave_condition"] == "time-varying (3 nodes)"
    assert meta["wave_condition_source"] == "given"
    assert meta["wave_track"] == track.to_dict()
    nodes = meta["wave_noise"]
    assert [n["condition"] for n in nodes] == ["calm", "wave-a0.10-f1.00", "wave-a0.05-f0.75"]
    assert [n["how"] for n in nodes] == ["calm", "node", "node"]
    np.testing.assert_allclose(nodes[2]["dvl_std"], TABLE_I_A05_F075)
    constant = localize(wave_log, "proposed")
    assert not np.array_equal(run.x, constant.x)  # the noise is not the constant one
    assert np.all(np.isfinite(run.x)) and np.all(np.isfinite(run.P))
    baseline = localize(wave_log, "baseline", wave=track)  # no wave noise: None, as today
    assert baseline.metadata["wave_noise"] is None
    assert baseline.metadata["wave_condition"] == "time-varying (3 nodes)"


def test_nodes_outside_the_profile(wave_log):
    """Nodes outside the profile are extrapolated by the orbital velocity (one warning naming the
    count), whatever the track's source; extrapolate=True keeps the nearest characterized
    condition as is (no warning), extrapolate="refuse" an error naming the node's time (never
    for an estimated track)."""
    t, a, f = np.array([0.0, 20.0, 40.0]), np.array([0.1, 0.5, 0.6]), np.array([1.0, 3.0, 3.0])
    given = WaveTrack(t, a, f, "scenario")
    with pytest.raises(ConfigError, match=r"node at t = 20\.000 s: wave condition wave-a0\.50"):
        localize(wave_log, "proposed", wave=given, extrapolate="refuse")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # --extrapolate: asked for, no warning
        nearest = localize(wave_log, "proposed", wave=given, extrapolate=True)
    assert [n["how"] for n in nearest.metadata["wave_noise"]] == ["node", "nearest", "nearest"]
    with pytest.warns(RuntimeWarning, match=r"2 of 3 wave track node\(s\) are outside") as record:
        physics = localize(wave_log, "proposed", wave=given)
    assert sum("wave track node" in str(w.message) for w in record) == 1
    how = [n["how"] for n in physics.metadata["wave_noise"]]
    assert how == ["node", "extrapolated", "extrapolated"]
    with pytest.warns(RuntimeWarning, match=r"2 of 3 wave track node"):
        estimated = localize(wave_log, "proposed", wave=WaveTrack(t, a, f, "estimated"),
                             extrapolate="refuse")  # fmt: skip
    assert _same(estimated, physics)


def test_auto_uses_the_estimate_from_the_log(wave_log, monkeypatch):
    """wave="auto" asks undertow.seastate for the sea state (replaced here by a stub:
    the estimator has its own tests) and filters with its track, as if given."""
    track = WaveTrack(np.array([5.0, 35.0]), np.array([0.05, 0.1]), np.array([0.75, 1.0]),
                      "estimated")  # fmt: skip
    calls = []

    class Estimate:
        def track(self):
            return track

        def to_dict(self):
            return {"stub": True}

    def estimate_sea_state(log, **kwargs):
        calls.append(log)
        return Estimate()

    monkeypatch.setattr(seastate, "estimate_sea_state", estimate_sea_state)
    run = localize(wave_log, "proposed", wave="auto")
    assert calls == [wave_log]
    meta = run.metadata
    assert meta["wave_condition_source"] == WAVE_ESTIMATED
    assert meta["wave_estimate"] == {"stub": True}
    assert meta["wave_track"] == track.to_dict()
    assert _same(run, localize(wave_log, "proposed", wave=track))
    assert _same(localize(wave_log, "proposed", wave=" AUTO"), run)


@pytest.mark.slow
def test_auto_with_the_real_estimator(wave_log):
    """End to end with undertow.seastate on a run whose wave the simulator knows (a = 0.10 m,
    f = 1.00 Hz): the track the filter used finds it at every node (amplitude within 10 %,
    frequency within 2 %), and the filter fed the estimate is as accurate in vx as the filter
    given the true condition (within 5 %)."""
    run = localize(wave_log, "proposed", wave="auto")
    meta = run.metadata
    assert meta["wave_condition_source"] == WAVE_ESTIMATED
    assert isinstance(meta["wave_estimate"], dict)
    track = meta["wave_track"]
    np.testing.assert_allclose(track["amplitude_m"], 0.10, rtol=0.10)
    np.testing.assert_allclose(track["frequency_hz"], 1.00, rtol=0.02)
    given = localize(wave_log, "proposed")  # the condition the log records: the true one
    truth = wave_log.ground_truth
    auto_vx = trajectory_rmse(run, truth).rmse["vx_m_s"]
    assert auto_vx == pytest.approx(trajectory_rmse(given, truth).rmse["vx_m_s"], rel=0.05)
