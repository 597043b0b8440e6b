"""The README's Python example runs as written (it is the first thing a user copies)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_readme_has_one_short_python_example():
    blocks = _python_blocks(README.read_text())
    assert len(blocks) == 1
    lines = [line for line in blocks[0].splitlines() if line.strip()]
    assert len(lines) <= 14  # a short example: imports plus about ten lines


@pytest.mark.slow
def test_readme_python_example_runs_and_prints_rmse_and_cells(tmp_path):
    code = _python_blocks(README.read_text())[0]
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
        timeout=300, check=True,
    ).stdout  # fmt: skip
    rmse_line, cells_line = out.strip().splitlines()[-2:]
    assert "'x_m'" in rmse_line and "'yaw_rad'" in rmse_line
    cells = int(cells_line.split()[0])
    assert cells > 100 and cells_line.endswith("occupied cells")
    assert list(tmp_path.iterdir()) == []  # the example writes nothing
