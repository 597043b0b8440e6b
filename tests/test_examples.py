"""The examples run as written (they are documentation)."""

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.slow
def test_localize_and_map_example_runs_and_reports_sane_numbers():
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / "localize_and_map.py"), "wave-a0.05-f0.75", "3"],
        capture_output=True, text=True, timeout=300, check=True,
    ).stdout  # fmt: skip
    assert "RMSE:" in out and "occupied cells" in out
    c2c = float(out.split("C2C ")[1].split()[0])
    assert c2c < 0.1  # cell centres lie half a cell (0.05 m) from a floor on a cell boundary
