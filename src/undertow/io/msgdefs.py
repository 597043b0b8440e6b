"""Message definitions the readers and the writer need beyond the ROS 2 Humble standard set.

- ``waterlinked_a50_ros_driver/msg/DVL`` and ``DVLBeam``: the Water Linked A50 ROS driver's
  messages, field types as embedded in real ROS 1 bags of that driver (``int64 id``,
  ``float64`` values, ``int64 status``, ``string form``).
- ``marine_acoustic_msgs/msg/Dvl``: the standard DVL message of the ``marine_msgs`` repository
  (apl-ocean-engineering), without its comment lines.
- ``dvl_msgs/msg/DVL``, ``DVLBeam`` and ``DVLDR``: Water Linked's ROS 2 driver
  (``dvl-a50-ros-driver``, ROS 2 branch, package ``dvl_msgs``), as embedded in real mcap bags of
  that driver.
- ``uuv_sensor_ros_plugins_msgs/msg/DVL`` and ``DVLBeam``: UUV Simulator's DVL
  (uuvsimulator/uuv_simulator); ``cola2_msgs/msg/DVL`` and ``DVLBeam`` (IQUA Robotics' COLA2,
  whose DVL message is "extracted from UUV Simulator": the same fields).
- ``ds_sensor_msgs/msg/Dvl`` with ``ds_core_msgs/msg/DsHeader``: WHOI Deep Submergence Lab's
  ``ds_msgs``.
- ``undertow_msgs/msg/RangeConfidence``: undertow's own, the confidence (0..1, NaN unknown) of the
  ``sensor_msgs/Range`` with the same header stamp (the Ping1D's ``distance`` message carries a
  confidence in %, Blue Robotics' ping-protocol; ``sensor_msgs/Range`` has no field for it):
  written by :func:`undertow.io.rosbag_write.write_log` and the live recorder on
  ``/ping_sonar/confidence`` beside the range, read back into ``SonarRange.confidence``.

ROS 1 bags and ROS 2 mcap files carry each topic's own definition, which rosbags registers and
which wins over these; they serve ROS 2 sqlite3 bags (before Iron), which carry none.

:func:`dvl_typestore` returns a ROS 2 Humble typestore with these types registered.
"""

from __future__ import annotations

from functools import cache

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

A50_DVL = "waterlinked_a50_ros_driver/msg/DVL"
A50_BEAM = "waterlinked_a50_ros_driver/msg/DVLBeam"
MARINE_DVL = "marine_acoustic_msgs/msg/Dvl"
RANGE_CONFIDENCE = "undertow_msgs/msg/RangeConfidence"

RANGE_CONFIDENCE_MSG = """\
std_msgs/Header header
float64 confidence
"""

A50_DVL_MSG = """\
std_msgs/Header header
float64 time
geometry_msgs/Vector3 velocity
float64 fom
float64 altitude
DVLBeam[] beams
bool velocity_valid
int64 status
string form
"""

A50_BEAM_MSG = """\
int64 id
float64 velocity
float64 distance
float64 rssi
float64 nsd
bool valid
"""

MARINE_DVL_MSG = """\
uint8 DVL_MODE_BOTTOM=1
uint8 DVL_MODE_WATER=2
uint8 DVL_TYPE_PISTON=0
uint8 DVL_TYPE_PHASED_ARRAY=1
std_msgs/Header header
uint8 velocity_mode
uint8 dvl_type
geometry_msgs/Vector3 velocity
float64[9] velocity_covar
float64 altitude
float64 course_gnd
float64 speed_gnd
uint8 num_good_beams
float32 sound_speed
bool beam_ranges_valid
bool beam_velocities_valid
geometry_msgs/Vector3[4] beam_unit_vec
float64[4] range
float32[4] range_covar
float32[4] beam_quality
float32[4] beam_velocity
float32[4] beam_velocity_covar
"""

WL_DVL = "dvl_msgs/msg/DVL"
WL_BEAM = "dvl_msgs/msg/DVLBeam"
WL_DVLDR = "dvl_msgs/msg/DVLDR"
UUV_DVL = "uuv_sensor_ros_plugins_msgs/msg/DVL"
UUV_BEAM = "uuv_sensor_ros_plugins_msgs/msg/DVLBeam"
COLA2_DVL = "cola2_msgs/msg/DVL"
COLA2_BEAM = "cola2_msgs/msg/DVLBeam"
DS_DVL = "ds_sensor_msgs/msg/Dvl"
DS_HEADER = "ds_core_msgs/msg/DsHeader"

#: the ROS 1 driver's fields and a 3x3 covariance (row-major, (m/s)^2; empty: unknown)
WL_DVL_MSG = A50_DVL_MSG.replace("float64 fom\n", "float64 fom\nfloat64[] covariance\n")

WL_DVLDR_MSG = """\
std_msgs/Header header
float64 time
geometry_msgs/Vector3 position
float64 pos_std
float64 roll
float64 pitch
float64 yaw
string type
int64 status
string format
"""

UUV_DVL_MSG = """\
std_msgs/Header header
geometry_msgs/Vector3 velocity
float64[9] velocity_covariance
float64 altitude
DVLBeam[] beams
"""

UUV_BEAM_MSG = """\
float64 range
float64 range_covariance
float64 velocity
float64 velocity_covariance
geometry_msgs/PoseStamped pose
"""

DS_HEADER_MSG = """\
builtin_interfaces/Time io_time
uint64[2] source_uuid
"""

DS_DVL_MSG = """\
uint8 DVL_MODE_BOTTOM=1
uint8 DVL_MODE_WATER=2
uint8 DVL_COORD_BEAM=0
uint8 DVL_COORD_INSTRUMENT=1
uint8 DVL_COORD_SHIP=2
uint8 DVL_COORD_EARTH=3
std_msgs/Header header
ds_core_msgs/DsHeader ds_header
float64 dvl_time
geometry_msgs/Vector3 velocity
float64[9] velocity_covar
float64 altitude
float64 course_gnd
float64 speed_gnd
uint8 num_good_beams
float32 speed_sound
geometry_msgs/Vector3[4] beam_unit_vec
float64[4] range
float32[4] range_covar
float32[4] raw_velocity
float32[4] raw_velocity_covar
uint8 velocity_mode
uint8 coordinate_mode
"""

CUSTOM_MSGDEFS = {
    A50_BEAM: A50_BEAM_MSG,
    A50_DVL: A50_DVL_MSG,
    MARINE_DVL: MARINE_DVL_MSG,
    WL_BEAM: A50_BEAM_MSG,  # the same beam fields as the ROS 1 driver's
    WL_DVL: WL_DVL_MSG,
    WL_DVLDR: WL_DVLDR_MSG,
    UUV_BEAM: UUV_BEAM_MSG,
    UUV_DVL: UUV_DVL_MSG,
    COLA2_BEAM: UUV_BEAM_MSG,
    COLA2_DVL: UUV_DVL_MSG,
    DS_HEADER: DS_HEADER_MSG,
    DS_DVL: DS_DVL_MSG,
    RANGE_CONFIDENCE: RANGE_CONFIDENCE_MSG,
}


@cache
def dvl_typestore() -> Typestore:
    """A ROS 2 Humble typestore that also knows the types of :data:`CUSTOM_MSGDEFS`."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict = {}
    for name, text in CUSTOM_MSGDEFS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
