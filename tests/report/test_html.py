"""The HTML report: one self-contained, well-formed page with every table, figure, the 3D
viewer's data, the config and the versions, from a real simulate -> localize -> map run."""

import base64
import html
import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest
import yaml
from scipy.spatial import cKDTree

from undertow.errors import DataError
from undertow.estimation import localize
from undertow.mapping.config import MappingConfig
from undertow.mapping.run import map_log
from undertow.report import figures, markdown_to_html, write_report
from undertow.report.html import VIEWER_POINTS
from undertow.sim import load_scenario, simulate

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source",
        "track", "wbr"}  # fmt: skip

MARKDOWN = """# Results

Simulated values, mean over 1 seed; `x < y` holds.

## Table II: RMSE

| variant | x (m) | yaw (rad) |
|---|---:|:---:|
| baseline | 0.862 | 0.015 |
| proposed | 0.869 | 0.003 |

- first note
- second note
"""


class Checker(HTMLParser):
    """Collects tags, attributes and script bodies; checks that elements nest and close."""

    def __init__(self):
        super().__init__()
        self.stack, self.errors, self.attrs, self.scripts = [], [], [], {}
        self._script = None

    def handle_starttag(self, tag, attrs):
        self.attrs.append((tag, dict(attrs)))
        if tag not in VOID:
            self.stack.append(tag)
        if tag == "script":
            self._script = dict(attrs).get("id", "")
            self.scripts[self._script] = ""

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:]}")
        else:
            self.stack.pop()
        if tag == "script":
            self._script = None

    def handle_data(self, data):
        if self._script is not None:
            self.scripts[self._script] += data


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    sim = simulate(load_scenario("rock-survey"), seed=1)
    traj = localize(sim.log, variant="proposed")
    occupancy = map_log(sim.log, traj, MappingConfig(method="adaptive")).map
    map_points = occupancy.points()
    figs = [
        ("Kernel <shapes> (paper Fig. 7).", figures.plot_kernel_shapes(out / "k.png", 0.1, 0.2)),
        ("Velocity (paper Fig. 8).", figures.plot_velocity(out / "v.png", sim.log, traj)),
    ]
    config = {"scenario": "rock-survey", "seeds": [1], "mapping": {"resolution": 0.1}}
    versions = {"undertow": "0.0-test", "numpy": np.__version__}
    tables = {"table2": {"baseline": {"x_m": 0.862}}, "missing": float("nan")}
    path = write_report(
        out / "report.html", title="Wave basin <report>", tables_markdown=MARKDOWN,
        tables=tables, figures=figs, map_points=map_points, ground_truth_points=sim.floor_cloud,
        config=config, versions=versions, notes=["claim **holds** (1/1)"],
    )  # fmt: skip
    page = path.read_text(encoding="utf-8")
    checker = Checker()
    checker.feed(page)
    checker.close()
    return dict(path=path, page=page, checker=checker, figs=figs, map_points=map_points,
                cloud=sim.floor_cloud, config=config)  # fmt: skip


@pytest.mark.slow
def test_page_is_well_formed_html(report):
    c = report["checker"]
    assert report["page"].startswith("<!DOCTYPE html>")
    assert c.errors == []
    assert c.stack == []  # every element closed
    assert [t for t, _ in c.attrs].count("html") == 1


@pytest.mark.slow
def test_page_is_self_contained(report):
    page = report["page"]
    assert "http://" not in page and "https://" not in page
    for tag, attrs in report["checker"].attrs:
        for key in ("src", "href"):
            value = attrs.get(key)
            if value is not None:
                assert value.startswith(("data:", "#")), (tag, key, value[:40])
    assert [t for t, _ in report["checker"].attrs].count("link") == 0  # no external CSS


@pytest.mark.slow
def test_figures_embedded_byte_for_byte_with_captions(report):
    imgs = [a["src"] for t, a in report["checker"].attrs if t == "img"]
    assert len(imgs) == len(report["figs"])
    for src, (caption, png) in zip(imgs, report["figs"], strict=True):
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1]) == png.read_bytes()
        assert html.escape(caption) in report["page"]


@pytest.mark.slow
def test_tables_rendered(report):
    page = report["page"]
    assert "<h1>Results</h1>" in page and "<h2>Table II: RMSE</h2>" in page
    assert '<td style="text-align:right">0.862</td>' in page
    assert '<td style="text-align:center">0.003</td>' in page
    assert "<code>x &lt; y</code>" in page
    assert "<li>second note</li>" in page
    assert "<strong>holds</strong>" in page
    embedded = json.loads(report["checker"].scripts["tables-data"], parse_constant=_no_nan)
    assert embedded == {"table2": {"baseline": {"x_m": 0.862}}, "missing": None}


def _no_nan(name):
    raise ValueError(f"invalid JSON constant {name}")


@pytest.mark.slow
def test_viewer_data_subsampled_and_faithful(report):
    data = json.loads(report["checker"].scripts["viewer-data"], parse_constant=_no_nan)
    mp = np.reshape(data["map"], (-1, 3)) + data["centre"]
    gt = np.reshape(data["gt"], (-1, 3)) + data["centre"]
    assert 0 < len(mp) and 0 < len(gt) and len(mp) + len(gt) <= VIEWER_POINTS
    assert len(mp) == min(len(report["map_points"]), 15_000)
    assert len(data["map_bin"]) == len(mp)
    assert set(data["map_bin"]) <= set(range(len(data["palette"])))
    # every embedded point is one of the inputs (to the 1 mm rounding)
    assert cKDTree(report["map_points"]).query(mp)[0].max() < 2e-3
    assert cKDTree(report["cloud"]).query(gt)[0].max() < 2e-3
    assert '<canvas id="viewer">' in report["page"]


@pytest.mark.slow
def test_config_and_versions(report):
    pre = re.findall(r"<pre>(.*?)</pre>", report["page"], re.S)
    assert any(yaml.safe_load(html.unescape(p)) == report["config"] for p in pre)
    assert "<td>undertow</td><td>0.0-test</td>" in report["page"]
    assert "Wave basin &lt;report&gt;" in report["page"]


def test_missing_figure_is_an_error_and_writes_nothing(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        write_report(
            tmp_path / "r.html", title="t", tables_markdown="", tables={},
            figures=[("gone", tmp_path / "missing.png")], map_points=np.zeros((0, 3)),
            ground_truth_points=np.zeros((0, 3)), config={}, versions={}, notes=[],
        )  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_markdown_table_converter():
    out = markdown_to_html("| a | b |\n|:--|--:|\n| <x> | 2 |\n| short |\n\nplain | text")
    assert '<th style="text-align:left">a</th>' in out
    assert '<td style="text-align:right">2</td>' in out
    assert "&lt;x&gt;" in out and "<x>" not in out
    assert out.count("<tr>") == 3  # header + 2 rows; the short row is padded
    assert "<p>plain | text</p>" in out
