"""A bag read in pieces (:func:`undertow.io.iter_log_pieces`): the pieces' streams end to end
are the whole read's, array for array, on the fixtures' bags and on real recordings."""

import warnings

import numpy as np
import pytest
from conftest import REAL_DATA
from io_fixtures import T0, full_log

from undertow.errors import ConfigError
from undertow.io import iter_log_pieces, read_log, write_log
from undertow.io.rosbag import PIECE_METADATA
from undertow.log import STREAM_NAMES


def _assert_pieces_are_the_whole(whole, pieces, evidence: bool = True) -> None:
    """Every stream of ``whole`` is its pieces' rows end to end (a multibeam's pings padded to
    the most beams of the whole log); every piece has the whole read's metadata (``evidence``
    False: its decisions only, the figures they were decided on may differ) and mounting."""
    assert len(pieces) > 2
    for name in STREAM_NAMES:
        stream = getattr(whole, name)
        parts = [getattr(p, name) for p in pieces if getattr(p, name) is not None]
        if stream is None:
            assert not parts, name
            continue
        np.testing.assert_array_equal(np.concatenate([p.t for p in parts]), stream.t)
        for field in stream.array_fields():
            value = getattr(stream, field)
            if value is None:
                assert all(getattr(p, field) is None for p in parts), (name, field)
                continue
            got = [np.asarray(getattr(p, field)) for p in parts]
            if name == "multibeam" and field in ("points", "intensity"):  # pad to whole width
                width = value.shape[1]
                got = [np.pad(g, [(0, 0), (0, width - g.shape[1])] + [(0, 0)] * (g.ndim - 2),
                              constant_values=np.nan) for g in got]  # fmt: skip
            np.testing.assert_array_equal(np.concatenate(got), value, err_msg=f"{name}.{field}")
    keep = {k: v for k, v in whole.metadata.items() if k not in PIECE_METADATA}
    for piece in pieces:
        if evidence:
            assert {k: v for k, v in piece.metadata.items() if k not in PIECE_METADATA} == keep
        assert piece.metadata["time_base"]["base"] == keep["time_base"]["base"]
        assert piece.metadata.get("imu_units", {}).get("unit") == keep.get("imu_units", {}).get(
            "unit"
        )
        assert piece.metadata.get("surface_pressure_pa") == keep.get("surface_pressure_pa")
        assert piece.mounting == whole.mounting
    tov = whole.metadata.get("dvl_time_of_validity_s")
    if tov is not None:
        got = [p.metadata["dvl_time_of_validity_s"] for p in pieces if p.dvl is not None]
        np.testing.assert_array_equal(np.concatenate(got), tov)


def _pieces(path, piece_s, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_log(path), list(iter_log_pieces(path, piece_s, **kwargs))


@pytest.mark.parametrize("flavor", ["driver", "standard"])
def test_pieces_of_a_bag_with_every_stream_are_the_whole_read(tmp_path, flavor):
    path = write_log(full_log(n=60), tmp_path / "bag", flavor=flavor)
    whole, pieces = _pieces(path, 0.7)
    assert len(pieces) >= 8  # 6 s of log
    _assert_pieces_are_the_whole(whole, pieces)
    for piece in pieces[1:-1]:  # each piece holds its window only
        assert piece.imu.t[-1] - piece.imu.t[0] < 0.7


def test_decisions_come_from_the_head_not_from_each_piece(tmp_path):
    """A log whose first piece alone would choose differently (hPa pressures, then Pa) gets the
    head's choice in every piece: decided once, from the first decide_s seconds."""
    log = full_log(n=60)
    hpa = log.pressure.pressure / 100.0
    log = log.replace(pressure=log.pressure.__class__(t=log.pressure.t, pressure=hpa))
    path = write_log(log, tmp_path / "bag")
    whole, pieces = _pieces(path, 1.0)
    _assert_pieces_are_the_whole(whole, pieces)
    np.testing.assert_allclose(whole.pressure.pressure, hpa * 100.0)
    # decided from the first 1.5 s only: still the same choices on this log
    _, short = _pieces(path, 1.0, decide_s=1.5)
    _assert_pieces_are_the_whole(whole, short, evidence=False)


@pytest.mark.realdata
@pytest.mark.parametrize("name, piece_s", [("a50_ros1_circle.bag", 3.0),
                                           ("coug_a50_imu_ros2", 2.0)])  # fmt: skip
def test_pieces_of_real_recordings_are_the_whole_read(name, piece_s):
    whole, pieces = _pieces(REAL_DATA / name, piece_s)
    _assert_pieces_are_the_whole(whole, pieces)


def test_piece_length_must_be_positive_and_other_formats_come_whole(tmp_path):
    path = write_log(full_log(), tmp_path / "bag")
    with pytest.raises(ConfigError, match="piece_s"):
        next(iter_log_pieces(path, 0.0))
    text = tmp_path / "a50.jsonl"
    text.write_text(
        '{"type": "velocity", "time": 1.0, "vx": 0.1, "vy": 0, "vz": 0, "fom": 0.01, '
        '"altitude": 1.0, "velocity_valid": true, "status": 0, "time_of_validity": '
        f'{int(T0 * 1e6)}, "time_of_transmission": {int(T0 * 1e6)}}}\n'
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (only,) = list(iter_log_pieces(text, 1.0))
    assert len(only.dvl) == 1


def test_the_bags_index_decides_the_pieces_and_an_asked_choice_wins(tmp_path, monkeypatch):
    """:func:`undertow.io.piece_choice`: the span and message count of the bag's index (those
    of its messages read one by one), pieces above either limit, whole below; --in-pieces and
    --whole as asked; a file that is not a bag whole. The line is said only off today's path."""
    from rosbags.highlevel import AnyReader

    import undertow.io
    from undertow.io import piece_choice
    from undertow.io.msgdefs import dvl_typestore

    path = write_log(full_log(n=60), tmp_path / "bag")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = read_log(path)
    times = np.concatenate([getattr(whole, name).t for name in whole.streams()])
    with AnyReader([path], default_typestore=dvl_typestore()) as reader:
        messages = sum(1 for _ in reader.messages())
    short = piece_choice(path)
    assert short.span_s == pytest.approx(times.max() - times.min(), abs=1e-6)
    assert short.messages == messages
    assert not short.pieces and short.policy == "auto" and short.line(path) is None
    monkeypatch.setattr(undertow.io, "PIECES_ABOVE_S", short.span_s - 0.01)
    long = piece_choice(path, piece_s=2.0)
    assert long.pieces and long.policy == "auto" and long.piece_s == 2.0
    assert "read in 2 s pieces" in long.line(path) and "--whole" in long.line(path)
    asked = piece_choice(path, False)
    assert not asked.pieces and "read whole as asked (--whole" in asked.line(path)
    monkeypatch.setattr(undertow.io, "PIECES_ABOVE_S", short.span_s + 0.01)
    assert not piece_choice(path).pieces
    monkeypatch.setattr(undertow.io, "PIECES_ABOVE_MESSAGES", messages - 1)
    assert piece_choice(path).pieces
    asked = piece_choice(path, True)
    assert asked.pieces and asked.policy == "asked" and "as asked (--in-pieces" in asked.line(path)
    text = tmp_path / "a50.jsonl"
    text.write_text('{"type": "velocity", "time_of_validity": 1}\n')
    assert not piece_choice(text, True).pieces
    with pytest.raises(ConfigError, match="piece_s"):
        piece_choice(path, piece_s=0.0)


def test_pieces_of_chosen_streams_are_those_streams_of_the_whole_read(tmp_path):
    path = write_log(full_log(n=60), tmp_path / "bag")
    whole, pieces = _pieces(path, 1.0, streams=("pressure", "dvl", "dvl_json"))
    assert {name for piece in pieces for name in piece.streams()} == {"pressure", "dvl"}
    for name in ("pressure", "dvl"):
        got = [getattr(p, name) for p in pieces if getattr(p, name) is not None]
        np.testing.assert_array_equal(np.concatenate([s.t for s in got]), getattr(whole, name).t)
    np.testing.assert_array_equal(np.concatenate([p.dvl.altitude for p in pieces]),
                                  whole.dvl.altitude)  # fmt: skip
