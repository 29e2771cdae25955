"""Readers for the files users already have, each turning into a station capture.

| format | files | library |
|---|---|---|
| ``px4`` | PX4 ULog ``.ulg`` | pyulog |
| ``ardupilot`` | ArduPilot DataFlash ``.bin`` | pymavlink ``DFReader`` |
| ``tlog`` | MAVLink telemetry log ``.tlog`` | pymavlink ``mavutil.mavmmaplog`` |
| ``ros`` | ROS 1 ``.bag``, ROS 2 bag folder / ``.db3`` / ``.mcap``, MCAP | rosbags |
| ``euroc`` | EuRoC / Kalibr IMU CSV | (plain text) |
| ``csv`` | any CSV, through ``--map`` and ``--unit`` | (plain text) |

UI-free: each reader returns an :class:`~station.importers._common.Imported`;
:func:`station.importers.load.import_file` makes the :class:`~station.capture.Capture` that
``station import`` writes and :func:`~station.importers.load.load_capture` the one ``calibrate``
and ``diagnose`` use directly. Every failure is an InputError, one line. The command-line
options live in ``options.py``, which loads no numpy (``station --help`` stays fast).
"""
