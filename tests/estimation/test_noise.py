"""Wave noise profiles: the paper's Table I at the nodes, linear in between, errors outside."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.estimation.noise import NoiseProfile

TABLE_I = {  # (a, f): (vx, vy, vz) std devs, m/s, the paper's tab:wave_table
    (0.10, 1.00): (0.025, 0.010, 0.003),
    (0.10, 0.75): (0.040, 0.010, 0.003),
    (0.05, 0.75): (0.011, 0.010, 0.003),
}


def test_table_entries_reproduced_at_nodes():
    prof = NoiseProfile.paper()
    for (a, f), std in TABLE_I.items():
        by_name = prof.noise(f"wave-a{a:.2f}-f{f:.2f}")
        assert by_name.dvl_std.tolist() == list(std) and by_name.how == "node"
        # the interpolator itself reproduces the nodes (queried a hair away from the node)
        near = prof.noise((a * (1 - 1e-12), f))
        np.testing.assert_allclose(near.dvl_std, std, rtol=1e-9)
    assert prof.noise("calm").dvl_std.tolist() == [0.0, 0.0, 0.0]
    assert prof.noise((0.0, 3.0)).how == "calm"


def test_linear_between_nodes():
    prof = NoiseProfile.paper()
    mid = prof.noise((0.10, 0.875))  # on the a = 0.1 edge: the mean of its two nodes
    np.testing.assert_allclose(mid.dvl_std, [0.0325, 0.010, 0.003], atol=1e-12)
    half = prof.noise((0.025, 0.75))  # halfway from calm to (0.05, 0.75)
    np.testing.assert_allclose(half.dvl_std, [0.0055, 0.005, 0.0015], atol=1e-12)
    assert mid.how == "interpolated"


def test_outside_hull_errors_unless_extrapolate():
    prof = NoiseProfile.paper()
    with pytest.raises(ConfigError, match="outside"):
        prof.noise((0.2, 1.0))
    near = prof.noise("wave-a0.20-f1.00", extrapolate=True)
    assert near.how == "nearest" and near.dvl_std.tolist() == [0.025, 0.010, 0.003]
    with pytest.raises(ConfigError):
        prof.noise("big waves")


def test_yaml_round_trip(tmp_path):
    prof = NoiseProfile.paper()
    back = NoiseProfile.from_yaml(prof.to_yaml(tmp_path / "p.yaml"))
    assert back.to_dict() == prof.to_dict()
    (tmp_path / "bad.yaml").write_text("conditions: [{amplitude_m: 0.1}]")
    with pytest.raises(ConfigError):
        NoiseProfile.from_yaml(tmp_path / "bad.yaml")


def test_measured_condition_answers_to_its_canonical_name():
    from undertow.estimation.noise import NoiseProfile

    profile = NoiseProfile.from_dict(
        {
            "conditions": [
                {"name": "calm", "amplitude_m": 0.0, "frequency_hz": None, "dvl_std": [0, 0, 0]},
                {"amplitude_m": 0.0999, "frequency_hz": 1.0003, "dvl_std": [0.02, 0.001, 0.0]},
            ]
        }
    )
    assert profile.noise((0.1, 1.0)).how == "node"
    np.testing.assert_allclose(profile.noise("wave-a0.10-f1.00").dvl_std, [0.02, 0.001, 0.0])
    # one frequency + calm: linear in amplitude along that frequency (exact at half amplitude)
    half = profile.noise((0.0999 / 2, 1.0003))
    assert half.how == "interpolated"
    np.testing.assert_allclose(half.dvl_std, [0.01, 0.0005, 0.0], atol=1e-12)
    with pytest.raises(ConfigError, match="outside"):
        profile.noise((0.05, 0.8))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("name: x\n", "p.yaml: noise profile field conditions: Field required"),
        ("conditions: [{amplitude_m: 0.1, frequency_hz: 1}]", "conditions.0.dvl_std: Field req"),
        ("conditions: [{amplitude_m: 0.1, dvl_std: [0, 0, 0]}]", "conditions.0.frequency_hz: a wa"),
        ("conditions: [{amplitude_m: x, dvl_std: [0, 0, 0]}]", "conditions.0.amplitude_m: Input"),
        ("[1, 2]\n", "p.yaml: not a noise profile"),
    ],
)
def test_invalid_profile_names_the_file_and_field(tmp_path, text, message):
    (tmp_path / "p.yaml").write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        NoiseProfile.from_yaml(tmp_path / "p.yaml")
    assert "Error(" not in str(info.value) and "\n" not in str(info.value)
