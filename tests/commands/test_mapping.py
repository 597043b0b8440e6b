"""`undertow map` and `undertow evaluate map` at the command line: input mistakes give one line
naming the file and what was expected, the normalization used is recorded, time spans checked."""

import json
import time

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app
from undertow.trajectory import Trajectory

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory, simulation, simulated_run):
    """A simulated calm carriage run on disk, and its ground truth as a trajectory (18 states,
    a small position variance growing along the run) instead of a filter's output."""
    root = tmp_path_factory.mktemp("cli_mapping")
    sim = simulation("calm", 0)
    (root / "run").symlink_to(simulated_run("calm", 0))
    gt = sim.log.ground_truth
    keep = slice(None, None, 20)  # 100 Hz is plenty for interpolation
    t = gt.t[keep]
    x = np.zeros((t.size, 18))
    x[:, :3], x[:, 3:6] = gt.position[keep], gt.orientation[keep]
    P = np.zeros((t.size, 18, 18))
    for k in range(3):
        P[:, k, k] = 1e-4 + 1e-3 * (t - t[0]) / (t[-1] - t[0])
    Trajectory(t, x, P, variant="ground truth").save_npz(root / "est" / "trajectory.npz")
    shifted = Trajectory(t + 1e4, x, P, variant="shifted")
    shifted.save_npz(root / "shifted" / "trajectory.npz")
    third = slice(0, t.size // 3)
    Trajectory(t[third], x[third], P[third]).save_npz(root / "third" / "trajectory.npz")
    return root


def _map(run, out, *extra):
    return runner.invoke(
        app, ["map", str(run / "run" / "log"), "--out", str(out), "-q", *extra]
    )  # fmt: skip


def _one_error_line(result):
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 1, result.output
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    return lines[0]


@pytest.mark.slow
def test_config_records_the_normalization_and_variance_bounds_fix_it(run, tmp_path):
    r = _map(run, tmp_path / "session", "--trajectory", str(run / "est"), "--method", "adaptive")
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load((tmp_path / "session" / "config.yaml").read_text())
    assert doc["mapping"]["variance_bounds"] is None
    mapper = doc["result"]["mapper"]
    assert mapper["normalization"] == "session"
    # per session: the bounds are the min and max of the variance the trajectory carried
    np.testing.assert_allclose(mapper["variance_bounds"][0], [1e-4] * 3, rtol=0.02)
    np.testing.assert_allclose(mapper["variance_bounds"][1], [1.1e-3] * 3, rtol=0.02)

    bounds = "0,0,0,0.002,0.002,0.002"
    r = _map(run, tmp_path / "fixed", "--trajectory", str(run / "est"), "--variance-bounds", bounds,
             "--method", "adaptive")  # fmt: skip
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load((tmp_path / "fixed" / "config.yaml").read_text())
    assert doc["mapping"]["variance_bounds"] == [[0.0] * 3, [0.002] * 3]
    assert doc["result"]["mapper"]["normalization"] == "fixed"
    assert doc["result"]["mapper"]["variance_bounds"] == [[0.0] * 3, [0.002] * 3]
    # the variance reaches only about half of the fixed range: shorter kernels, fewer cells
    assert (
        doc["result"]["occupied_cells"]
        < yaml.safe_load((tmp_path / "session" / "config.yaml").read_text())["result"][
            "occupied_cells"
        ]
    )

    est = ["--trajectory", str(run / "est")]
    line = _one_error_line(_map(run, tmp_path / "a", *est, "--variance-bounds", "1,2,3"))
    assert "six comma-separated numbers" in line
    line = _one_error_line(_map(run, tmp_path / "b", *est, "--variance-bounds", "0,0,0,1,1,1",
                                "--method", "csm"))  # fmt: skip
    assert "adaptive" in line
    line = _one_error_line(_map(run, tmp_path / "c", *est, "--variance-bounds", "2,0,0,1,1,1"))
    assert "variance_bounds" in line


@pytest.mark.slow
def test_a_trajectory_of_another_time_span_is_an_error_and_a_partial_one_warns(run, tmp_path):
    line = _one_error_line(_map(run, tmp_path / "m", "--trajectory", str(run / "shifted")))
    assert "no range measurement falls inside the trajectory's time span" in line
    t = Trajectory.load_npz(run / "shifted").t
    assert f"trajectory {t[0]:.3f} .. {t[-1]:.3f} s, ranges (dvl, sonar) 0.000 .. " in line
    assert not (tmp_path / "m").exists()
    r = _map(run, tmp_path / "part", "--trajectory", str(run / "third"))
    assert r.exit_code == 0, r.output
    warnings = [ln for ln in r.output.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 1 and "outside the trajectory's time span" in warnings[0]


def test_wrong_kinds_of_input_files_say_what_was_expected(run, tmp_path):
    tum, ply = run / "run" / "ground_truth.tum", run / "run" / "ground_truth.ply"
    line = _one_error_line(_map(run, tmp_path / "m", "--trajectory", str(ply)))
    assert line == (
        f"error: {ply}: a PLY point cloud, expected a trajectory.npz written by `undertow "
        "localize` (or its folder), or a TUM file (t tx ty tz qx qy qz qw)"
    )
    settings = tmp_path / "settings.yaml"
    settings.write_text("mapping: {method: csm}\n")
    line = _one_error_line(_map(run, tmp_path / "m", "--trajectory", str(run / "est"),
                                "--prior", str(settings)))  # fmt: skip
    assert line == (
        f"error: prior {settings}: a YAML file, expected a map.npz written by `undertow map` "
        "(or its folder)"
    )
    line = _one_error_line(runner.invoke(app, ["evaluate", "map", str(tum), str(ply)]))
    assert line == (
        f"error: {tum}: a TUM trajectory, expected a map.npz written by `undertow map` (or its "
        "folder)"
    )


@pytest.mark.slow
def test_evaluate_map_threshold_and_empty_clouds(run, tmp_path):
    out = tmp_path / "map"
    assert _map(run, out, "--trajectory", str(run / "est")).exit_code == 0
    gt = str(run / "run" / "ground_truth.ply")
    for bad in ("1.5", "0", "1", "-0.2"):
        line = _one_error_line(runner.invoke(app, ["evaluate", "map", str(out), gt,
                                                   "--threshold", bad]))  # fmt: skip
        assert line == f"error: threshold must be in (0, 1), got {float(bad)}"
    line = _one_error_line(
        runner.invoke(app, ["evaluate", "map", str(out / "map.ply"), gt, "--threshold", "0.7"])
    )
    assert line.startswith("error: threshold applies to a map.npz; ")
    # the map's PLY and its map.npz at the default threshold are the same points
    from_ply = runner.invoke(app, ["evaluate", "map", str(out / "map.ply"), gt, "--json"])
    from_npz = runner.invoke(app, ["evaluate", "map", str(out), gt, "--json"])
    assert from_ply.exit_code == from_npz.exit_code == 0
    a, b = json.loads(from_ply.stdout), json.loads(from_npz.stdout)
    assert a["occupied_cells"] == b["occupied_cells"] > 0
    assert a["c2c_mean_m"] == pytest.approx(b["c2c_mean_m"], abs=1e-6)
    # a higher threshold keeps fewer cells
    high = runner.invoke(app, ["evaluate", "map", str(out), gt, "--json", "--threshold", "0.95"])
    assert json.loads(high.stdout)["occupied_cells"] < b["occupied_cells"]

    empty = tmp_path / "empty.ply"
    empty.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     "property float y\nproperty float z\nend_header\n")  # fmt: skip
    line = _one_error_line(runner.invoke(app, ["evaluate", "map", str(out), str(empty)]))
    assert line == f"error: {empty}: the ground-truth cloud has no points"
    r = runner.invoke(app, ["evaluate", "map", str(empty), gt, "--json"])
    assert r.exit_code == 0, r.output
    assert f"{empty}: the map has no points" in r.stderr
    data = json.loads(r.stdout)
    assert data["occupied_cells"] == 0 and data["c2c_mean_m"] is None


@pytest.mark.slow
def test_a_resolution_too_fine_for_memory_is_refused_in_one_line(run, tmp_path):
    """1e-4 m cells: one sample's kernel support alone is ~10^8 chunks (hundreds of GB), refused
    at once instead of eating the machine; a modest resolution over a small limit is refused
    after counting the chunks the supports touch."""
    est = ["--trajectory", str(run / "est")]
    start = time.perf_counter()
    line = _one_error_line(_map(run, tmp_path / "a", *est, "--resolution", "1e-4"))
    assert time.perf_counter() - start < 30
    assert (
        "at resolution 0.0001 m would need an estimated" in line and "mapping.max_memory_gb" in line
    )
    settings = tmp_path / "small.yaml"
    settings.write_text("mapping: {max_memory_gb: 0.001}\n")
    line = _one_error_line(_map(run, tmp_path / "b", *est, "--config", str(settings)))
    assert "limit 0.001 GB" in line
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    for resolution, message in (("0", "greater than 0"), ("2", "not above resolution / 10")):
        line = _one_error_line(_map(run, tmp_path / "c", *est, "--resolution", resolution))
        assert "mapping.resolution" in line or message in line
        assert message in line


@pytest.mark.slow
def test_evaluate_map_uses_the_threshold_the_map_was_made_with(run, tmp_path):
    from undertow.occupancy import OccupancyMap

    settings = tmp_path / "strict.yaml"
    settings.write_text("mapping: {occupied_threshold: 0.999999}\n")
    out = tmp_path / "map"
    r = _map(run, out, "--trajectory", str(run / "est"), "--config", str(settings))
    assert r.exit_code == 0, r.output
    made = yaml.safe_load((out / "config.yaml").read_text())["result"]["occupied_cells"]
    gt = str(run / "run" / "ground_truth.ply")
    data = json.loads(runner.invoke(app, ["evaluate", "map", str(out), gt, "--json"]).stdout)
    assert data["occupied_cells"] == made
    assert data["threshold"] == 0.999999 and "the map" in data["threshold_from"]
    text = runner.invoke(app, ["evaluate", "map", str(out), gt]).stdout
    assert "0.999999 (the map (mapping.occupied_threshold))" in text
    given = runner.invoke(app, ["evaluate", "map", str(out), gt, "--json", "--threshold", "0.5"])
    assert json.loads(given.stdout)["occupied_cells"] > made
    assert json.loads(given.stdout)["threshold_from"] == "--threshold"
    # a map written before the threshold was recorded: 0.5, and the output says so
    old = OccupancyMap.load(out)
    legacy = tmp_path / "legacy.npz"
    meta = {k: v for k, v in old.metadata.items() if k != "occupied_threshold"}
    OccupancyMap(old.cells, old.alpha, old.beta, old.resolution, old.alpha0, old.beta0,
                 metadata=meta).save(legacy)  # fmt: skip
    data = json.loads(runner.invoke(app, ["evaluate", "map", str(legacy), gt, "--json"]).stdout)
    assert data["threshold"] == 0.5 and data["threshold_from"].startswith("default 0.5")
    assert data["occupied_cells"] == json.loads(given.stdout)["occupied_cells"]


@pytest.mark.slow
def test_prior_may_be_a_map_folder(run, tmp_path):
    est = ["--trajectory", str(run / "est")]
    assert _map(run, tmp_path / "first", *est, "--method", "csm").exit_code == 0
    r = _map(run, tmp_path / "second", *est, "--method", "csm", "--prior", str(tmp_path / "first"))
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load((tmp_path / "second" / "config.yaml").read_text())
    assert doc["result"]["mapper"]["seeded_from"] == str(tmp_path / "first" / "map.npz")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--method", "csm", "--length-scale", "0.3"], "length_scale applies to the bki method"),
        (["--length-scale", "0.3"], "length_scale applies to the bki method, not tpu"),
        (
            ["--method", "bki", "--variance-bounds", "0,0,0,1,1,1"],
            "variance_bounds applies to the adaptive method, not bki",
        ),
    ],
)
def test_options_of_another_method_are_errors(run, tmp_path, args, message):
    line = _one_error_line(_map(run, tmp_path / "m", "--trajectory", str(run / "est"), *args))
    assert message in line


def test_both_range_streams_disabled_says_so(run, tmp_path):
    settings = tmp_path / "none.yaml"
    settings.write_text("mapping: {use_dvl: false, use_sonar: false}\n")
    line = _one_error_line(
        _map(run, tmp_path / "m", "--trajectory", str(run / "est"), "--config", str(settings))
    )
    assert "use_dvl and use_sonar are both false in the config" in line
    assert "the log has none" not in line


@pytest.mark.slow
def test_a_python_user_gets_the_map_and_warnings_of_the_cli(run, tmp_path):
    """`map_file` / `evaluate_map_file` (what the commands call) from Python: the same map,
    result facts and warnings as `undertow map`, the same numbers as `undertow evaluate map`."""
    from undertow.commands.mapping import evaluate_map_file, map_file
    from undertow.occupancy import OccupancyMap

    r = _map(run, tmp_path / "cli", "--trajectory", str(run / "third"), "--method", "bki")
    assert r.exit_code == 0, r.output
    cli_warnings = [ln.removeprefix("warning: ") for ln in r.output.splitlines()
                    if ln.startswith("warning:")]  # fmt: skip
    result = map_file(run / "run" / "log", run / "third", method="bki", out_dir=tmp_path / "py")
    assert len(cli_warnings) == 1 and result.warnings == cli_warnings
    doc = yaml.safe_load((tmp_path / "cli" / "config.yaml").read_text())
    assert doc == {"mapping": result.config.model_dump(mode="json"), "result": result.metadata}
    assert (tmp_path / "py" / "config.yaml").read_text() == (
        tmp_path / "cli" / "config.yaml"
    ).read_text()
    assert (tmp_path / "py" / "map.ply").read_bytes() == (tmp_path / "cli" / "map.ply").read_bytes()
    for written in (OccupancyMap.load(tmp_path / "cli"), OccupancyMap.load(tmp_path / "py")):
        for name in ("cells", "alpha", "beta"):
            np.testing.assert_array_equal(getattr(written, name), getattr(result.map, name))
        assert written.metadata == result.map.metadata
    gt = run / "run" / "ground_truth.ply"
    cli = runner.invoke(app, ["evaluate", "map", str(tmp_path / "cli"), str(gt), "--json"])
    assert cli.exit_code == 0, cli.output
    assert evaluate_map_file(tmp_path / "cli", gt).to_dict() == json.loads(cli.stdout)


def test_a_too_long_bag_is_mapped_in_pieces_where_the_method_allows(run, tmp_path, monkeypatch):
    """With the limit below the calm run's 48 s, `map --method csm` reads it in pieces by
    itself (one line; ``read_in_pieces`` in config.yaml; CSM's counts those of --whole), and
    a method that normalizes over the whole log reads it whole, saying why in one line."""
    import undertow.io

    monkeypatch.setattr(undertow.io, "PIECES_ABOVE_S", 10.0)
    est, csm = ["--trajectory", str(run / "est")], ["--method", "csm", "--resolution", "0.2"]
    auto = _map(run, tmp_path / "auto", *est, *csm)
    said = [ln for ln in auto.output.splitlines() if "pieces" in ln]
    assert auto.exit_code == 0 and len(said) == 1 and "--whole reads" in said[0], auto.output
    doc = yaml.safe_load((tmp_path / "auto" / "config.yaml").read_text())
    assert doc["result"]["read_in_pieces"]["policy"] == "auto"
    whole = _map(run, tmp_path / "whole", *est, *csm, "--whole")
    assert whole.exit_code == 0 and "read whole as asked (--whole" in whole.output, whole.output
    assert "read_in_pieces" not in yaml.safe_load((tmp_path / "whole" / "config.yaml").read_text())
    a, b = (np.load(tmp_path / f / "map.npz") for f in ("auto", "whole"))
    order = [np.lexsort(np.asarray(m["cells"]).T[::-1]) for m in (a, b)]
    for key in ("cells", "alpha", "beta"):
        np.testing.assert_array_equal(a[key][order[0]], b[key][order[1]])
    adaptive = _map(run, tmp_path / "adaptive", *est, "--method", "adaptive", "--resolution",
                    "0.2")  # fmt: skip
    said = adaptive.output
    assert "read whole (its index spans" in said and "the adaptive method" in said, said
