"""The command line: thin commands, one clear line for user errors, JSON that parses."""

import json

from conftest import REAL_DATA
from typer.testing import CliRunner

from undertow.cli import app

REAL = REAL_DATA
runner = CliRunner()


def test_info_json_on_the_real_ros1_bag():
    result = runner.invoke(app, ["info", str(REAL / "a50_ros1_circle.bag"), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    dvl = next(s for s in data["streams"] if s["name"] == "dvl")
    assert dvl["messages"] == 378


def test_missing_file_is_one_line_and_exit_1():
    result = runner.invoke(app, ["info", "/no/such/run.bag"])
    assert result.exit_code == 1
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "/no/such/run.bag" in lines[0]
    assert "Traceback" not in result.output


def test_help_has_examples():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0 and "undertow simulate" in result.output
