"""A flight controller stand-in for tests: a pymavlink process that sends HEARTBEATs to a UDP
endpoint and streams RAW_IMU (ArduPilot's mG/mrad/s/mGauss) only after it is asked
(REQUEST_DATA_STREAM or MAV_CMD_SET_MESSAGE_INTERVAL); it answers MAV_CMD_REQUEST_MESSAGE for
AUTOPILOT_VERSION and PARAM_REQUEST_LIST. Usage: python mavlink_peer.py URL SECONDS
(URL: udpout:127.0.0.1:PORT, or tcp:127.0.0.1:PORT to connect to a listening station)"""

import sys
import time

from pymavlink import mavutil

url, seconds = sys.argv[1], float(sys.argv[2])
t_start = time.monotonic()
while True:  # a TCP station may not listen yet
    try:
        conn = mavutil.mavlink_connection(url, source_system=1, source_component=1, retries=0)
        break
    except OSError:
        if time.monotonic() - t_start > 20:
            raise
        time.sleep(0.1)
mav = conn.mav
PARAMS = [
    ("INS_ACCOFFS_X", 0.05),
    ("INS_ACCOFFS_Y", -0.02),
    ("INS_ACCOFFS_Z", 0.11),
    ("INS_ACCSCAL_X", 1.001),
    ("INS_ACCSCAL_Y", 0.998),
    ("INS_ACCSCAL_Z", 1.003),
    ("INS_ACC_ID", 2753028),
    ("AHRS_ORIENTATION", 0),
    ("BATT_CAPACITY", 3300),
]
streaming, t0, last_hb, k = False, time.monotonic(), 0.0, 0
while time.monotonic() - t0 < seconds:
    now = time.monotonic()
    if now - last_hb > 0.2:
        mav.heartbeat_send(
            mavutil.mavlink.MAV_TYPE_QUADROTOR,
            mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
            0,
            0,
            0,
        )
        last_hb = now
    m = conn.recv_match(blocking=True, timeout=0.005)
    if m is not None:
        t = m.get_type()
        if t == "REQUEST_DATA_STREAM" or (
            t == "COMMAND_LONG" and m.command == mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        ):
            streaming = True
        elif t == "COMMAND_LONG" and m.command == mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE and int(m.param1) == 148:
            mav.autopilot_version_send(
                0,
                0x040500FF,
                0,
                0,
                0,
                b"\0" * 8,
                b"\0" * 8,
                b"\0" * 8,
                0,
                0,
                0x0123456789ABCDEF,
            )
        elif t == "PARAM_REQUEST_LIST":
            for i, (name, value) in enumerate(PARAMS):
                ptype = (
                    mavutil.mavlink.MAV_PARAM_TYPE_INT32
                    if isinstance(value, int)
                    else mavutil.mavlink.MAV_PARAM_TYPE_REAL32
                )
                mav.param_value_send(name.encode(), float(value), ptype, len(PARAMS), i)
    if streaming:
        while k < (time.monotonic() - t0) * 200:  # 200 Hz by the clock, in bursts
            mav.raw_imu_send(int(k * 5000), 10, -20, 1000, 5, -3, 1, 200, -100, 400)
            k += 1
