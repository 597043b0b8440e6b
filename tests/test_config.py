"""The joined settings file: defaults with no file, partial files, one-line errors, CLI use."""

import pytest
from typer.testing import CliRunner

from undertow.cli import app
from undertow.config import Settings
from undertow.errors import ConfigError
from undertow.estimation.localize import LocalizerConfig
from undertow.mapping.config import MappingConfig


def test_no_file_gives_every_stage_default():
    s = Settings.from_yaml(None)
    assert s.mapping == MappingConfig() and s.localizer == LocalizerConfig()
    assert s.localizer_params() == {}


def test_partial_file_sets_only_what_it_names(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("localizer: {variant: be}\nmapping: {method: csm}\ntopics: {imu: [/my/imu]}\n")
    s = Settings.from_yaml(path)
    assert s.localizer_params() == {"variant": "be"}
    assert s.mapping.method == "csm" and s.mapping.resolution == 0.1
    assert s.topics.imu == ["/my/imu"]


@pytest.mark.parametrize(
    "text, where",
    [
        ("mapping: {resolution: -1}", "mapping.resolution"),
        ("localise: {}", "localise"),
        ("- 1", "mapping"),
    ],
)
def test_errors_name_file_and_field(tmp_path, text, where):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=f"bad.yaml: .*{where}"):
        Settings.from_yaml(path)


def test_cli_reports_a_bad_settings_file_in_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("localizer: {variant: nope}\n")
    result = CliRunner().invoke(
        app, ["localize", "x.bag", "--config", str(path), "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 1 and "localizer.variant" in result.output
    assert "Traceback" not in result.output
