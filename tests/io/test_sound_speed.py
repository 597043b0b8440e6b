"""The water's sound speed (undertow.io.sound_speed): Coppens' equation against published
speeds in pure water, and the correction against the simulator's physics and a real log."""

import warnings

import numpy as np
import pytest
from conftest import REAL_DATA
from pydantic import ValidationError

from undertow.estimation.calibration import calibrate
from undertow.io import LogOptions, read_log
from undertow.io.sound_speed import coppens_sound_speed, correct_sound_speed
from undertow.sim import Scenario, load_scenario, simulate


@pytest.mark.parametrize(
    ("temperature", "expected"),
    # pure water at one atmosphere: Del Grosso and Mader, JASA 52(5B), 1972 (m/s)
    [(0.0, 1402.39), (10.0, 1447.27), (20.0, 1482.34), (30.0, 1509.13)],
)
def test_coppens_in_fresh_water_gives_the_pure_water_speeds(temperature, expected):
    assert coppens_sound_speed(temperature, 0.0) == pytest.approx(expected, abs=0.3)


def test_coppens_in_sea_water_at_its_reference_salinity():
    # at S = 35 the salinity term vanishes: the cubic in t alone, 1449.05 m/s at 0 C
    assert coppens_sound_speed(0.0, 35.0) == pytest.approx(1449.05)
    assert coppens_sound_speed(10.0, 35.0) > coppens_sound_speed(10.0, 0.0) + 40.0


def _scenario(dvl_set: float, sonar_set: float) -> Scenario:
    base = load_scenario("calm").to_yaml_dict()
    base["dvl"] = {**base.get("dvl", {}), "sound_speed_setting": dvl_set}
    base["sonar"] = {**base.get("sonar", {}), "sound_speed_setting": sonar_set}
    base["water"] = {**base.get("water", {}), "sound_speed_m_s": 1476.0}
    base["ground_truth"] = {**base.get("ground_truth", {}), "rate_hz": 50.0}
    return Scenario.model_validate(base)


@pytest.fixture(scope="module")
def runs():
    """The same run (seed) with the DVL set to 1500 m/s and the Ping to 1490 in water of
    1476 m/s, and with both set to the water's own."""
    wrong = simulate(_scenario(1500.0, 1490.0), seed=4).log
    right = simulate(_scenario(1476.0, 1476.0), seed=4).log
    return wrong, right


def test_the_corrected_ranges_are_those_of_sensors_set_to_the_water(runs):
    wrong, right = runs
    options = LogOptions(sound_speed_m_s=1476.0, sonar_sound_speed_m_s=1490.0)
    with pytest.warns(UserWarning, match=r"sound speed 1476\.0 m/s .* x 0\.98400 .* x 0\.99060"):
        fixed = correct_sound_speed(wrong, options)
    for name in ("beam_range", "altitude"):
        a, b = getattr(fixed.dvl, name), getattr(right.dvl, name)
        np.testing.assert_allclose(a[np.isfinite(b)], b[np.isfinite(b)], rtol=1e-12)
    ok = np.isfinite(right.sonar.range) & np.isfinite(fixed.sonar.range)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(fixed.sonar.range[ok], right.sonar.range[ok], rtol=1e-12)
    record = fixed.metadata["sound_speed"]
    assert record["water_m_s"] == 1476.0 and record["dvl_factor"] == pytest.approx(1476 / 1500)
    good = np.isfinite(wrong.dvl.altitude)  # the log given is left as it was
    np.testing.assert_allclose(wrong.dvl.altitude[good], fixed.dvl.altitude[good] * 1500 / 1476)


def test_the_calibration_finds_no_scale_left_after_the_correction(runs):
    """The calm run's DVL scale factor, fitted against the ground truth (independent of the
    correction), is c_set / c before it and 1 after it."""
    wrong, _ = runs
    before = calibrate(wrong).dvl_scale_factor
    fixed = correct_sound_speed(wrong, LogOptions(sound_speed_m_s=1476.0), state=False)
    after = calibrate(fixed).dvl_scale_factor
    assert before == pytest.approx(1500.0 / 1476.0, rel=2e-3)
    assert after == pytest.approx(1.0, abs=2e-3)


def test_a_temperature_gives_coppens_speed_for_the_water():
    options = LogOptions(water_temperature_c=20.0)
    log = simulate(_scenario(1500.0, 1500.0), seed=1).log
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fixed = correct_sound_speed(log, options)
    c = coppens_sound_speed(20.0, 0.0)
    record = fixed.metadata["sound_speed"]
    assert record["water_m_s"] == pytest.approx(c)
    assert "fresh water at 20 C" in record["source"]
    np.testing.assert_allclose(fixed.dvl.velocity, log.dvl.velocity * c / 1500.0)
    np.testing.assert_allclose(fixed.dvl.covariance, log.dvl.covariance * (c / 1500.0) ** 2)
    salt = correct_sound_speed(log, LogOptions(water_temperature_c=20.0, water="salt"), False)
    assert salt.metadata["sound_speed"]["water_m_s"] == pytest.approx(coppens_sound_speed(20, 35))


def test_without_a_sound_speed_the_log_is_kept_and_says_so():
    log = simulate(_scenario(1500.0, 1500.0), seed=1).log
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kept = correct_sound_speed(log, LogOptions())
    assert kept.dvl is log.dvl and kept.sonar is log.sonar
    assert kept.metadata["sound_speed"]["source"] == "not corrected"


@pytest.mark.realdata
def test_a_real_log_read_with_a_sound_speed_is_corrected_and_records_it():
    path = REAL_DATA / "a50_tcp_json_v1_straight.txt"
    raw = read_log(path)
    with pytest.warns(UserWarning, match="a50_tcp_json_v1_straight.txt: sound speed 1450.0"):
        fixed = read_log(path, options=LogOptions(sound_speed_m_s=1450.0))
    k = 1450.0 / 1500.0
    for name in ("beam_range", "altitude", "velocity"):
        a, b = np.asarray(getattr(fixed.dvl, name)), np.asarray(getattr(raw.dvl, name))
        np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
        np.testing.assert_allclose(a[np.isfinite(a)], k * b[np.isfinite(b)])
    assert fixed.metadata["sound_speed"]["dvl_factor"] == pytest.approx(k)
    assert fixed.metadata["sound_speed"]["dvl_set_from"] == "the A50's fixed value, assumed"
    assert raw.metadata["sound_speed"]["source"] == "not corrected"


def test_the_dvl_setting_comes_from_its_messages_unless_set(tmp_path):
    """A standard DVL message (marine_acoustic_msgs/Dvl) says the sound speed it converted
    with: the reader takes it as the DVL's setting (the sidecar, which also records the
    simulated DVL's, is left out here); the settings still win."""
    import yaml

    from undertow.io import write_log

    log = simulate(_scenario(1475.0, 1500.0), seed=2).log
    bag = write_log(log, tmp_path / "bag", flavor="standard")
    sidecar = bag / "undertow.yaml"
    doc = yaml.safe_load(sidecar.read_text())
    del doc["metadata"]["dvl_sound_speed_m_s"]
    sidecar.write_text(yaml.safe_dump(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        read = read_log(bag, options=LogOptions(sound_speed_m_s=1476.0))
        given = read_log(bag, options=LogOptions(sound_speed_m_s=1476.0,
                                                 dvl_sound_speed_m_s=1500.0))  # fmt: skip
    assert read.metadata["dvl_sound_speed_m_s"] == 1475.0
    record = read.metadata["sound_speed"]
    assert record["dvl_set_from"] == "the log (its DVL messages' sound_speed)"
    assert record["dvl_factor"] == pytest.approx(1476.0 / 1475.0)
    assert given.metadata["sound_speed"]["dvl_factor"] == pytest.approx(1476.0 / 1500.0)
    np.testing.assert_allclose(read.dvl.altitude * 1475.0, given.dvl.altitude * 1500.0)


def test_one_sound_speed_or_one_temperature_not_both():
    with pytest.raises(ValidationError, match="not both"):
        LogOptions(sound_speed_m_s=1480.0, water_temperature_c=20.0)
    with pytest.raises(ValidationError):
        LogOptions(water_temperature_c=50.0)  # beyond Coppens' 0-35 C
    with pytest.raises(ValidationError):
        LogOptions(sound_speed_m_s=-1.0)
