"""MAVLink written by pymavlink into a real pty, read back by the station's reader with the
documented units (station/device/mavlink.py, docs/protocol.md)."""

from __future__ import annotations

import math
import os
import time
import tty

import numpy as np
import pytest
from pymavlink.dialects.v20 import all as mavlink2

from station.device.mavlink import MavlinkParser
from station.device.reader import Batch, Reader


class MasterFile:
    """What pymavlink's MAVLink(file=...) writes to: the pty master."""

    def __init__(self, fd: int):
        self.fd = fd

    def write(self, data) -> None:
        view = memoryview(bytes(data))
        while view:
            view = view[os.write(self.fd, view) :]


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


def read_all(reader: Reader, n: int, timeout_s: float = 60.0) -> Batch:
    got, total, end = [], 0, time.monotonic() + timeout_s
    while total < n and time.monotonic() < end:
        b = reader.drain()
        if b is not None:
            got.append(b)
            total += len(b)
        time.sleep(0.01)
    assert total >= n, f"{total} of {n}"
    return Batch.concat(got)


def settle(reader: Reader) -> None:
    """pyserial flushes input on open: write only once the reader has the port."""
    end = time.monotonic() + 60
    while not reader.stats().connected and time.monotonic() < end:
        time.sleep(0.01)
    time.sleep(0.05)


def test_highres_imu_is_read_in_si_units(pty_pair):
    master, path = pty_pair
    mav = mavlink2.MAVLink(MasterFile(master), srcSystem=1, srcComponent=1)
    with Reader(path, protocol="mavlink") as r:
        settle(r)
        mav.heartbeat_send(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, 0, 0, 0)
        for k in range(20):
            mav.highres_imu_send(
                1_000_000 + 5000 * k,
                0.25,
                -0.5,
                9.75,
                0.125,
                -0.0625,
                0.03125,
                0.21,
                -0.04,
                0.45,
                1013.0,
                0.0,
                0.0,
                31.5,
                0x1FFF,
                0,
            )
        b = read_all(r, 20)
        h, s = r.header, r.stats()
    assert (h.accel_unit, h.gyro_unit, h.mag_unit) == ("m/s^2", "rad/s", "gauss")
    assert s.gaps == 0 and s.parse_errors == 0
    # float32 on the wire: values exact where binary-exact, else within float32 rounding
    np.testing.assert_array_equal(b.values[:, :6], np.tile([0.25, -0.5, 9.75, 0.125, -0.0625, 0.03125], (20, 1)))
    np.testing.assert_allclose(b.values[:, 6:9], np.tile([0.21, -0.04, 0.45], (20, 1)), rtol=1e-7)
    np.testing.assert_array_equal(b.values[:, 9], 31.5)
    np.testing.assert_allclose(b.t_s, 0.005 * np.arange(20), atol=1e-9)


def test_scaled_imu2_milli_units_become_g_rad_s_gauss(pty_pair):
    master, path = pty_pair
    mav = mavlink2.MAVLink(MasterFile(master), srcSystem=7, srcComponent=1)
    with Reader(path, protocol="mavlink", mavlink_source="SCALED_IMU2") as r:
        settle(r)
        for k in range(10):
            # an ArduPilot-like mix: SCALED_IMU2 among RAW_IMU and SCALED_IMU
            mav.raw_imu_send(10_000 * k, 1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 0)
            mav.scaled_imu_send(10 * k, 0, 0, 999, 0, 0, 0, 0, 0, 0, 2000)
            mav.scaled_imu2_send(10 * k, 1000, -250, 981, 500, -20, 3, 250, -125, 400, 2512 if k else 0)
        b = read_all(r, 10)
        h, s = r.header, r.stats()
    assert h.device_id == "mavlink-7-1" and (h.accel_unit, h.gyro_unit, h.mag_unit) == ("g", "rad/s", "gauss")
    np.testing.assert_allclose(b.values[1, :9], [1.0, -0.25, 0.981, 0.5, -0.02, 0.003, 0.25, -0.125, 0.4], rtol=1e-12)
    assert math.isnan(b.values[0, 9]) and b.values[1, 9] == pytest.approx(25.12)  # 0 cdegC = no sensor
    np.testing.assert_allclose(b.t_s, 0.010 * np.arange(10), atol=1e-9)
    assert s.gaps == 0  # the other messages fill the packet sequence: nothing lost


def test_raw_imu_in_ardupilot_milli_units_and_lost_packets_are_gaps():
    """RAW_IMU as ArduPilot sends it (GCS_MAVLINK::send_raw_imu: mG, mrad/s, mGauss, cdegC)."""
    out = bytearray()

    class Buf:
        def write(self, data):
            out.extend(data)

    mav = mavlink2.MAVLink(Buf(), srcSystem=1, srcComponent=1)
    frames = []
    for k in range(6):
        start = len(out)
        mav.raw_imu_send(1000 * k, -1000, 2, 1000, 10, -10, 0, 300, -300, 0, 0, 2100)
        frames.append((start, len(out)))
    corrupt = bytearray(out)
    corrupt[frames[2][0] + 12] ^= 0xFF  # frame 2 fails its CRC
    lost = corrupt[: frames[4][0]] + corrupt[frames[5][0] :]  # frame 4 never arrives
    p = MavlinkParser()
    p.feed(bytes(lost))
    b = p.take()
    assert (p.header.accel_unit, p.header.gyro_unit, p.header.mag_unit) == ("g", "rad/s", "gauss")
    np.testing.assert_allclose(b.values[0, :9], [-1.0, 0.002, 1.0, 0.01, -0.01, 0.0, 0.3, -0.3, 0.0], rtol=1e-12)
    assert b.values[0, 9] == 21.0
    np.testing.assert_array_equal(b.seq, [0, 1, 3, 5])
    assert p.stats.errors["checksum"] == 1 and p.stats.gaps == 2


def test_raw_imu_from_another_autopilot_stays_in_counts():
    """A HEARTBEAT naming a non-ArduPilot autopilot before the stream: RAW_IMU kept as counts."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    data = mav.heartbeat_encode(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, 0, 0, 0).pack(mav)
    mav.seq += 1
    data += mav.raw_imu_encode(1000, -16384, 2, 16384, 10, -10, 0, 300, -300, 0, 0, 2100).pack(mav)
    p = MavlinkParser()
    p.feed(bytes(data))
    b = p.take()
    assert (p.header.accel_unit, p.header.gyro_unit, p.header.mag_unit) == ("counts", "counts", "counts")
    np.testing.assert_array_equal(b.values[0, :9], [-16384, 2, 16384, 10, -10, 0, 300, -300, 0])


def test_sender_whose_frames_all_carry_sequence_zero_loses_nothing():
    """pymavlink's pack() without send() leaves seq at 0 in every frame: 200 Hz for 4 s must give
    800 samples (it gave 1: each frame was taken as a repeat of the last); a frame sent twice
    byte for byte is still one sample."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [
        bytes(mav.highres_imu_encode(5000 * k, 0.1, 0.2, 9.8, 0, 0, 0, 0.2, 0, 0.4, 0, 0, 0, 25.0, 0x1FFF, 0).pack(mav))
        for k in range(800)
    ]
    assert {f[4] for f in frames} == {0}  # MAVLink 2 seq byte: all zero
    p = MavlinkParser()
    p.feed(b"".join(frames[:100] + [frames[99]] + frames[100:]))
    b = p.take()
    assert len(b.t_dev_us) == 800 and p.stats.duplicates == 1 and p.stats.gaps == 0
    np.testing.assert_allclose(np.diff(b.t_dev_us), 5000.0)


def test_record_from_the_simulated_flight_controller(tmp_path):
    """sim-device --protocol mavlink: HIGHRES_IMU (and SCALED_IMU) from the simulator through
    a pty into a capture: gravity comes out near 9.8 m/s^2 after the nominal factory scaling
    (the unit's own scale and bias errors, a few %, remain to calibrate)."""
    import threading

    from solvers.simulate import LiveImu
    from station.capture import read_capture
    from station.device.record import record
    from station.device.simdevice import SimDevice

    imu = LiveImu(procedure="accel-tabletop", seed=3, rate_hz=200.0)
    # a clean read-back: a 30 s UART buffer, so a reader the scheduler leaves out for over
    # 0.5 s (the default buffer; a loaded 2-core machine) loses nothing
    dev = SimDevice(imu, protocol="mavlink", mavlink_scaled=True, max_pending_s=30.0)
    stop = threading.Event()
    with dev:
        th = threading.Thread(target=dev.run, args=(stop,), daemon=True)
        th.start()
        try:
            res = record(
                dev.path,
                str(tmp_path / "fc.csv"),
                protocol="mavlink",
                seconds=1.0,
                mavlink_source="HIGHRES_IMU",
                header_timeout_s=30.0,  # a limit, not a pace: the 1 Hz heartbeat, late on a loaded machine
            )
        finally:
            stop.set()
            th.join(5)
    cap = read_capture(tmp_path / "fc.csv")
    assert cap.meta["accel_unit"] == "m/s^2" and cap.meta["mag_unit"] == "gauss"
    assert cap.meta["gaps"] == "0" and cap.meta["parse_errors"] == "0" and dev.stats.dropped == 0
    assert float(cap.meta["sample_rate_hz"]) == pytest.approx(200.0, rel=1e-3)
    g = np.linalg.norm(np.column_stack([cap.columns[k] for k in ("ax", "ay", "az")]), axis=1)
    assert np.median(g) == pytest.approx(9.80, rel=0.08)  # nominal scaling vs the unit's ~2 % scale, 0.03 V bias
    b = np.linalg.norm(np.column_stack([cap.columns[k] for k in ("mx", "my", "mz")]), axis=1)
    assert 0.2 < np.median(b) < 0.8  # the Earth's field in gauss, with hard/soft iron
    assert res.samples == cap.n_rows


@pytest.mark.parametrize(
    "station_url,peer_url", [("udp:127.0.0.1:{}", "udpout:127.0.0.1:{}"), ("tcpin:127.0.0.1:{}", "tcp:127.0.0.1:{}")]
)
def test_record_over_udp_a_stream_it_had_to_request(tmp_path, station_url, peer_url):
    """`station record --port udp:127.0.0.1:PORT` against a pymavlink peer process on this machine
    that streams RAW_IMU only once asked: the capture holds the requested stream in ArduPilot's
    units, is named by the board's AUTOPILOT_VERSION uid, and carries the parameters in use."""
    import socket
    import subprocess
    import sys
    from pathlib import Path

    from station.capture import read_capture

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM if station_url.startswith("udp") else socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "udp.csv"
    peer = subprocess.Popen(
        [sys.executable, str(root / "tests" / "mavlink_peer.py"), peer_url.format(port), "30"],
        stdout=subprocess.DEVNULL,
    )
    try:
        rec = subprocess.run(
            [
                sys.executable,
                "-m",
                "station",
                "record",
                "--port",
                station_url.format(port),
                "--protocol",
                "mavlink",
                "--seconds",
                "3",
                "--out",
                str(out),
            ],
            check=False,
            cwd=root,
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        peer.kill()
        peer.wait()
    assert rec.returncode == 0, rec.stderr
    cap = read_capture(out)
    assert cap.meta["device"] == "ardupilot-0123456789abcdef" and cap.meta["firmware"] == "ardupilot"
    assert cap.meta["corrected"] == "true" and cap.meta["param.INS_ACCOFFS_Z"] == "0.11"
    assert cap.meta["param.INS_ACC_ID"] == "2753028" and cap.meta["accel_device_id"] == "2753028"
    assert "param.BATT_CAPACITY" not in cap.meta  # only calibration parameters are kept
    assert cap.meta["params_received"] == "9/9"
    assert cap.meta["accel_unit"] == "g" and cap.n_rows > 50
    np.testing.assert_allclose(cap.columns["az"], 1.0)  # 1000 mG
    np.testing.assert_allclose(cap.columns["gx"], 0.005)  # 5 mrad/s


def test_px4_board_asked_for_highres_imu_and_its_integer_parameters_decoded_bytewise():
    """A PX4 board (HEARTBEAT autopilot PX4) with no uid: the station asks for AUTOPILOT_VERSION,
    then for the stream (MAV_CMD_SET_MESSAGE_INTERVAL of HIGHRES_IMU) and the parameter list;
    CAL_ACC0_ID arrives as PX4 sends INT32 parameters, its bytes inside the float."""
    import struct

    board = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)

    def frame(msg):
        data = bytes(msg.pack(board))
        board.seq = (board.seq + 1) % 256
        return data

    p = MavlinkParser(request_hz=250.0)
    p.feed(frame(board.heartbeat_encode(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, 0, 0, 0)))
    asked = MavlinkParser()  # decode what the station sent, with pymavlink
    sent = [m for f in p.take_outgoing() for m in asked._mav.parse_buffer(f) or []]
    assert [(m.get_type(), getattr(m, "command", None)) for m in sent] == [
        ("COMMAND_LONG", mavlink2.MAV_CMD_REQUEST_MESSAGE),
        ("PARAM_REQUEST_LIST", None),
    ]
    p.feed(frame(board.autopilot_version_encode(0, 0, 0, 0, 0, b"\0" * 8, b"\0" * 8, b"\0" * 8, 0, 0, 0, b"\0" * 18)))
    sent = [m for f in p.take_outgoing() for m in asked._mav.parse_buffer(f) or []]
    interval = [m for m in sent if getattr(m, "command", None) == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL]
    assert interval and interval[0].param1 == mavlink2.MAVLINK_MSG_ID_HIGHRES_IMU and interval[0].param2 == 4000.0
    as_float = struct.unpack("<f", struct.pack("<i", 1310988))[0]
    p.feed(frame(board.param_value_encode(b"CAL_ACC0_ID", as_float, mavlink2.MAV_PARAM_TYPE_INT32, 2, 0)))
    p.feed(frame(board.param_value_encode(b"CAL_ACC0_XOFF", 0.0125, mavlink2.MAV_PARAM_TYPE_REAL32, 2, 1)))
    p.feed(frame(board.highres_imu_encode(1000, 0, 0, 9.8, 0, 0, 0, 0.2, 0, 0.4, 0, 0, 0, 25.0, 0x1FFF, 0)))
    meta = p.board_meta()
    assert p.header.device_id == "mavlink-1-1"  # no uid on this board
    assert meta["firmware"] == "px4" and meta["param.CAL_ACC0_ID"] == "1310988"
    assert meta["param.CAL_ACC0_XOFF"] == "0.0125" and meta["accel_device_id"] == "1310988"
    assert meta["params_received"] == "2/2" and meta["corrected"] == "true"


def test_a_parameter_the_board_changes_while_streaming_is_params_changed_not_in_use():
    """An ArduPilot board sends PARAM_VALUE when it saves a parameter: COMPASS_LEARN = 3 sets the
    compass offsets in flight (Compass_learn.cpp) while the station records. The later value
    replaced the one the recorded samples were corrected with, silently; the export then composed
    with it. Now the first value stays param.*, the name is in params_changed."""
    board = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)

    def frame(msg):
        data = bytes(msg.pack(board))
        board.seq = (board.seq + 1) % 256
        return data

    p = MavlinkParser(request_hz=200.0)  # the station asks for the parameter list
    p.feed(frame(board.heartbeat_encode(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)))
    real = mavlink2.MAV_PARAM_TYPE_REAL32
    p.feed(frame(board.param_value_encode(b"COMPASS_OFS_X", 10.0, real, 3, 0)))
    p.feed(frame(board.param_value_encode(b"COMPASS_LEARN", 3.0, mavlink2.MAV_PARAM_TYPE_INT8, 3, 1)))
    p.feed(frame(board.param_value_encode(b"COMPASS_OFS_Y", -20.0, real, 3, 2)))
    p.feed(frame(board.param_value_encode(b"COMPASS_OFS_Y", -20.0, real, 3, 2)))  # the list sent again: no change
    p.feed(frame(board.param_value_encode(b"COMPASS_OFS_X", -35.0, real, 3, 65535)))  # learnt, saved
    meta = p.board_meta()
    assert meta["param.COMPASS_OFS_X"] == "10" and meta["param.COMPASS_OFS_Y"] == "-20"
    assert meta["params_changed"] == "COMPASS_OFS_X"
    # learnt offsets that reach the link only as SENSOR_OFFSETS (no PARAM_VALUE) change them too
    p.feed(frame(board.sensor_offsets_encode(10, -20, 4, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    p.feed(frame(board.sensor_offsets_encode(10, -20, 4, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    assert p.board_meta()["params_changed"] == "COMPASS_OFS_X"
    p.feed(frame(board.sensor_offsets_encode(10, -26, 4, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    assert p.board_meta()["params_changed"] == "COMPASS_OFS_X,COMPASS_OFS_Y"
