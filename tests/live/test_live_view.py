"""The live view: a WebSocket client sees every documented channel and one message on each."""

from __future__ import annotations

import asyncio
import json
import math
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.live.view import AUTOPILOT_TOPICS, TOPICS, LiveView
from undertow.occupancy import OccupancyMap

#: opens sockets on 127.0.0.1 (servers it starts)
pytestmark = pytest.mark.network

SUBPROTOCOL = "foxglove.sdk.v1"  # the only one the SDK's server accepts (0.30)
T = 1_700_000_123.25


def _publish_all(view: LiveView) -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=18)
    A = rng.normal(size=(18, 18))
    view.publish_pose(T, x, A @ A.T)
    view.publish_path(T, rng.normal(size=(5, 3)))
    origins = np.zeros((4, 3))
    view.publish_rays(T, origins, origins + [0, 0, 2.0], "dvl")
    view.publish_rays(T, origins[:1], [[0, 0, 3.0]], "sonar")
    cells = np.array([[0, 0, 10], [1, 0, 10], [2, 1, 11]])
    occupancy = OccupancyMap(cells, [5.0, 9.0, 1.0], [1.0, 1.0, 4.0], 0.1, 1.0, 1.0)
    view.publish_map(T, occupancy, color_by="variance")
    view.publish_wave(T, 0.05, 0.75)
    view.publish_autopilot_pose(T, [1.0, 2.0, 0.5], (0.0, 0.1, 1.5))
    ekf = {"flags": 25, "names": ["attitude", "pos_horiz_rel"], "pos_horiz_variance": math.nan}
    view.publish_autopilot_ekf(T, {**ekf, "sending": True})


async def _session(view: LiveView, topics: dict = TOPICS) -> tuple[dict, dict]:
    websockets = pytest.importorskip("websockets")
    url = f"ws://127.0.0.1:{view.port}"
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL]) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        channels: dict[str, dict] = {}
        while not set(topics) <= set(channels):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 5.0))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        subs = {k: channels[topic]["id"] for k, topic in enumerate(sorted(topics))}
        await ws.send(
            json.dumps(
                {
                    "op": "subscribe",
                    "subscriptions": [{"id": k, "channelId": c} for k, c in subs.items()],
                }
            )
        )
        deadline = time.monotonic() + 5.0
        while not all(view.subscribed(t) for t in topics) and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        _publish_all(view)
        got: dict[str, list] = {topic: [] for topic in topics}
        topic_of = {k: sorted(topics)[k] for k in subs}
        try:
            while True:  # everything published arrives; wait a little more for extras
                timeout = 5.0 if any(not v for v in got.values()) else 0.3
                frame = await asyncio.wait_for(ws.recv(), timeout)
                if isinstance(frame, bytes) and frame[0] == 0x01:  # MessageData
                    sub, stamp = struct.unpack_from("<IQ", frame, 1)
                    got[topic_of[sub]].append((stamp, frame[13:]))
        except TimeoutError:
            pass
    return channels, got


def test_client_sees_every_channel_and_one_message_on_each():
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    topics = {**TOPICS, **AUTOPILOT_TOPICS}
    view = LiveView("127.0.0.1", 0, autopilot=True)
    try:
        assert view.port > 0 and view.url == f"ws://127.0.0.1:{view.port}"
        channels, got = asyncio.run(_session(view, topics))
    finally:
        view.close()
    assert set(channels) == set(topics)
    for topic, schema in topics.items():
        assert channels[topic]["schemaName"] == schema, topic
        assert len(got[topic]) == 1, f"{topic}: {len(got[topic])} messages"
        assert got[topic][0][0] == 1_700_000_123_250_000_000  # log time = the estimate's t
    wave = json.loads(got["/undertow/wave"][0][1])
    assert wave == {"t": T, "amplitude_m": 0.05, "frequency_hz": 0.75}
    ekf = json.loads(got["/autopilot/ekf"][0][1])  # NaN as null (strict JSON)
    assert ekf["flags"] == 25 and ekf["pos_horiz_variance"] is None and ekf["sending"]
    view.close()  # idempotent


def test_the_autopilot_channels_only_with_autopilot():
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    view = LiveView("127.0.0.1", 0)
    try:
        channels, got = asyncio.run(_session(view))
    finally:
        view.close()
    assert set(channels) == set(TOPICS) and all(len(v) == 1 for v in got.values())


def test_misuse_is_one_line():
    pytest.importorskip("foxglove")
    with LiveView("127.0.0.1", 0) as view:
        _publish_all(view)  # nobody subscribed: nothing is built, nothing fails
        with pytest.raises(ConfigError, match="ray kind"):
            view.publish_rays(0.0, [[0, 0, 0]], [[0, 0, 1]], "laser")
        with pytest.raises(ConfigError, match="color_by"):
            view.publish_map(0.0, OccupancyMap(np.zeros((0, 3)), [], [], 0.1, 1, 1), "max")
        with pytest.raises(ConfigError, match="cannot serve"):
            LiveView("127.0.0.1", view.port)


def test_undertow_imports_without_foxglove_and_the_view_names_the_package():
    code = (
        "import sys; sys.modules['foxglove'] = None\n"
        "import undertow, undertow.cli, undertow.live.recorder, undertow.live.view as v\n"
        "from undertow.errors import ConfigError\n"
        "try:\n    v.LiveView('127.0.0.1', 0)\n"
        "except ConfigError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines() == [
        "live view: the Foxglove SDK is not installed (pip install foxglove-sdk)"
    ]


def test_uncertainty_ellipsoid_gives_back_the_covariance():
    """The 3-sigma ellipsoid's axes (diameters 2 * 3 sigma) along its orientation rebuild the
    position covariance: R diag((d / 6)^2) R^T = P (R from the quaternion sent), for random
    covariances (eigh's left-handed bases included) and a degenerate one."""
    from scipy.spatial.transform import Rotation

    from undertow.live.view import ellipsoid_axes

    rng = np.random.default_rng(3)
    left_handed = 0
    for k in range(200):
        A = rng.normal(size=(3, 3)) * (0.1 if k % 2 else 3.0)
        cov = A @ A.T if k else np.diag([4.0, 4.0, 0.0])
        size, q = ellipsoid_axes(cov)
        R = Rotation.from_quat(q).as_matrix()
        sigma = np.array(size) / 6.0
        scale = np.abs(cov).max()
        np.testing.assert_allclose(R @ np.diag(sigma**2) @ R.T, cov, atol=1e-9 * scale)
        assert q[3] >= 0 and min(size) >= 0
        left_handed += np.linalg.det(np.linalg.eigh(cov)[1]) < 0
    assert left_handed > 0  # the flip was exercised


def test_path_is_at_most_max_poses_evenly_spaced_newest_last():
    from undertow.live.view import MAX_PATH_POSES, path_points

    for n in (1, 5, MAX_PATH_POSES, MAX_PATH_POSES + 1, 3 * MAX_PATH_POSES + 7, 36_000):
        p = np.arange(3.0 * n).reshape(n, 3)
        out = path_points(p)
        assert 1 <= len(out) <= MAX_PATH_POSES
        assert np.array_equal(out[0], p[0]) and np.array_equal(out[-1], p[-1])
        rows = out[:, 0] // 3
        if n <= MAX_PATH_POSES:
            assert np.array_equal(out, p)
        else:  # every k-th, k the smallest step that fits, then the newest
            k = int(np.ceil(n / (MAX_PATH_POSES - 1)))
            assert np.all(np.diff(rows[:-1]) == k) and rows[-1] - rows[-2] <= k
    assert len(path_points(np.zeros((10, 3)), max_poses=4)) == 4


def test_the_views_map_takes_at_most_its_share_of_the_loop():
    from undertow.live.pipeline import MAP_VIEW_SHARE, STATUS_PERIOD_S, map_view_due

    assert map_view_due(100.0, 0.004) == 100.0 + STATUS_PERIOD_S  # cheap: every period
    slow = 4 * STATUS_PERIOD_S * MAP_VIEW_SHARE  # a rebuild 4 times the share of a period
    due = map_view_due(100.0, slow)
    assert due == pytest.approx(100.0 + 4 * STATUS_PERIOD_S)
    assert slow / (due - 100.0) == pytest.approx(MAP_VIEW_SHARE)
