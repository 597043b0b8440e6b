"""Message definitions the readers and the writer need beyond the ROS 2 Humble standard set.

- ``waterlinked_a50_ros_driver/msg/DVL`` and ``DVLBeam``: the Water Linked A50 ROS driver's
  messages, field types as embedded in real ROS 1 bags of that driver (``int64 id``,
  ``float64`` values, ``int64 status``, ``string form``).
- ``marine_acoustic_msgs/msg/Dvl``: the standard DVL message of the ``marine_msgs`` repository
  (apl-ocean-engineering), without its comment lines.

:func:`dvl_typestore` returns a ROS 2 Humble typestore with these types registered.
"""

from __future__ import annotations

from functools import cache

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

A50_DVL = "waterlinked_a50_ros_driver/msg/DVL"
A50_BEAM = "waterlinked_a50_ros_driver/msg/DVLBeam"
MARINE_DVL = "marine_acoustic_msgs/msg/Dvl"

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

CUSTOM_MSGDEFS = {A50_BEAM: A50_BEAM_MSG, A50_DVL: A50_DVL_MSG, MARINE_DVL: MARINE_DVL_MSG}


@cache
def dvl_typestore() -> Typestore:
    """A ROS 2 Humble typestore that also knows the A50 driver and marine_acoustic_msgs types."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict = {}
    for name, text in CUSTOM_MSGDEFS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
