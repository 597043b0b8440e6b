"""The live stage (``undertow live``): sensors in, the online estimate, a recording and a view out.

- :mod:`~undertow.live.links`: one thread per sensor protocol (A50 TCP JSON, Ping1D, MAVLink),
  reconnecting with backoff, stamping each measurement as a :class:`~undertow.records.Record`;
  :mod:`~undertow.live.sensors` opens the ones the ``live`` settings name;
- :mod:`~undertow.live.pipeline`: :class:`~undertow.live.pipeline.LiveSession`, the loop that
  records every record, time-orders them (:mod:`~undertow.live.reorder`), runs the online
  filter, map and sea state on them, previews the pose at each DVL report
  (:mod:`~undertow.live.preview`) and writes the results at the end;
- :mod:`~undertow.live.recorder`: the recording, a ROS 2 bag written as records arrive
  (:mod:`~undertow.live.cdr`, :mod:`~undertow.live.mcap_append`: its fast paths);
- :mod:`~undertow.live.view`: the live view, a Foxglove WebSocket server.

The protocols' codecs are formats of :mod:`undertow.io`, shared with the offline readers; the
virtual robot that plays a log as these sensors is the simulator's (:mod:`undertow.sim.robot`).
"""
