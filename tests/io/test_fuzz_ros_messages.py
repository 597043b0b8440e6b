"""Fuzzing of the field's DVL, depth and GPS messages: damaged bytes of a real AUV bag's excerpt
(``fuzz/corpus/coug_ros2``: the first 6 s of the shared ``coug_a50_imu_ros2`` recording) and
absurd field values in well-formed messages give one-line errors or counted warnings, never a
traceback; the good messages are kept."""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from io_fixtures import header, write_raw_bag
from test_fuzz_readers import _bag_bytes, outcome

from undertow.io import read_log
from undertow.io.msgdefs import WL_DVL, WL_DVLDR, dvl_typestore
from undertow.io.topics import TopicMap

SEED = Path(__file__).resolve().parents[2] / "fuzz" / "corpus" / "coug_ros2"
set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
FEW = hsettings(
    max_examples=8,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
T = dvl_typestore().types
T0 = 1_700_000_000.0
ODD = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -1.0]),
)


@FEW
@given(data=st.data())
def test_damaged_bytes_of_a_real_auv_bag(tmp_path, data):
    out = tmp_path / "bag"
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(SEED, out)
    mcap = next(out.glob("*.mcap"))
    mcap.write_bytes(_bag_bytes(data, mcap.read_bytes()))
    outcome(read_log, out)


def _vec(values):
    return T["geometry_msgs/msg/Vector3"](x=values[0], y=values[1], z=values[2])


@FEW
@given(values=st.lists(ODD, min_size=12, max_size=12), cov_len=st.sampled_from([0, 3, 9, 12]))
def test_absurd_fields_of_dvl_dvldr_and_fix_messages(values, cov_len):
    """One message of each type with absurd values among good ones: the good ones are read."""
    msgs = []
    for i in range(6):
        t = T0 + 0.2 * i
        odd = i == 3
        v = values[:3] if odd else [0.1, 0.0, 0.0]
        beam = T["dvl_msgs/msg/DVLBeam"](
            id=0, velocity=values[4], distance=values[5], rssi=0.0, nsd=0.0, valid=True
        )
        cov = np.full(cov_len if odd else 9, values[6])
        dvl = T[WL_DVL](header=header(t), time=values[7], velocity=_vec(v), fom=values[8],
                        covariance=cov, altitude=values[9], beams=[beam], velocity_valid=True,
                        status=0, form="")  # fmt: skip
        dr = T[WL_DVLDR](header=header(t), time=t, position=_vec(values[:3] if odd else [0, 0, 0]),
                         pos_std=values[10], roll=values[11] if odd else 0.0, pitch=0.0, yaw=0.0,
                         type="", status=0, format="")  # fmt: skip
        status = T["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
        fix = T["sensor_msgs/msg/NavSatFix"](
            header=header(t), status=status, latitude=values[0] if odd else 40.0,
            longitude=values[1] if odd else -111.0, altitude=values[2],
            position_covariance=np.full(9, values[6]), position_covariance_type=2)  # fmt: skip
        ns = int(t * 1e9)
        msgs += [("/dvl/data", WL_DVL, ns, dvl), ("/dvl/position", WL_DVLDR, ns, dr),
                 ("/gps/fix", "sensor_msgs/msg/NavSatFix", ns, fix)]  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "bag"
        write_raw_bag(bag, msgs)
        log = outcome(read_log, bag, TopicMap(dead_reckoning=["/dvl/position"]))
    assert log is not None and len(log.dvl) >= 5 and len(log.gps) >= 5
