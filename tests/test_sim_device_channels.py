"""P4 mode A (reference IMU) and P5 (LDV beams + INS/DGPS) over a real pseudo-terminal: the
simulated device (`station.device.simdevice.SimDevice`, the same simulators as the built-in
device) speaks protocol version 2, whose header names the extra channels (`ref_gx`..,
`vl1`.., `vx`..) and whose data sentences carry them; real pyserial reads them through the
station's reader; the real Textual app runs the guided screens by its pilot, keys only,
as on the in-process device (tests/test_tui_by_hand.py), and saves.

The device runs faster than life (``speed``: device seconds per wall second; its clock in
every sentence is its own), so a three-minute procedure takes seconds; the tests wait on
the app's state, never on time.
"""

from __future__ import annotations

import asyncio
import threading

import numpy as np

from db.store import Store
from station.app import make_app
from station.device.protocol import StationParser
from tests.test_tui import screen_name, screen_text
from tests.test_tui import wait_for as tui_wait_for

SIZE = (80, 24)


class Served:
    """A SimDevice streaming on a real pty in a thread (a context manager)."""

    def __init__(self, imu, speed: float = 1.0) -> None:
        from station.device.simdevice import SimDevice

        self.imu = imu
        self.dev = SimDevice(imu, speed=speed)
        self.path = self.dev.open()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.dev.run, args=(self.stop,), daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5)
        self.dev.close()


async def wait_for(pilot, cond, timeout_s=300.0):
    """tests.test_tui's wait with a longer safety net (not a pace): the device is on a real pty."""
    await tui_wait_for(pilot, cond, timeout_s=timeout_s)


async def connect(pilot, app, screen: str) -> None:
    await pilot.press("f5")
    await wait_for(pilot, lambda: screen_name(app) == screen and getattr(app.screen, "guide", None) is not None)


async def save(pilot, app) -> int:
    await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
    await pilot.press("s")
    await wait_for(pilot, lambda: app.screen.calibration_id is not None)
    return app.screen.calibration_id


def test_the_header_names_the_channels_and_a_version_1_reading_is_unchanged():
    """What goes on the wire: a version-2 header with the reference IMU's channels, data
    sentences with three more fields; a header without channels stays version 1."""
    from solvers.simulate import LiveImu, LiveVehicle
    from station.device.simdevice import SimDevice

    dev = SimDevice(LiveImu(procedure="gyro-drift", seed=1, reference=True))
    head = dev._header_bytes()
    assert head.startswith(b"$STH,2,SIM-GYR-0001,V,rad/s,uT,100,ref_gx,ref_gy,ref_gz*")
    data = dev._encode(dev.imu.read(3))
    assert all(line.count(b",") == 15 for line in data.splitlines())  # 13 + 3 values
    p = StationParser()
    p.feed(head + data)
    block = p.take()
    assert p.stats.parse_errors == 0 and sorted(block.extra) == ["ref_gx", "ref_gy", "ref_gz"]
    assert np.isfinite(block.extra["ref_gz"]).all() and np.isfinite(block.values[:, :10]).all()
    # a version-1 reader of the same bytes: a header of version 1 declares no channels, and
    # the trailing fields of a data sentence are ignored (the v1 rule)
    p1 = StationParser()
    v1_head = head.replace(b"$STH,2,", b"$STH,1,").split(b"*")[0][1:]
    from station.device.protocol import checksum

    p1.feed(b"$%s*%02X\r\n" % (v1_head, checksum(v1_head)) + data)
    b1 = p1.take()
    assert p1.stats.parse_errors == 0 and b1.extra == {} and np.array_equal(b1.values, block.values)
    # the vehicle: no accelerometer, no magnetometer, its body rates as the gyro, six channels
    car = SimDevice(LiveVehicle(seed=2))
    assert car._header_bytes().startswith(b"$STH,2,SIM-LDV-0002,,rad/s,,10,vl1,vl2,vl3,vx,vy,vz*")
    assert SimDevice(LiveImu(seed=3))._header_bytes().startswith(b"$STH,1,SIM-ACC-0003,V,rad/s,uT,100*")


def test_record_keeps_the_reference_channels(tmp_path):
    """`station record` from a reference-IMU device on a real pty: the capture has the
    ref_gx..ref_gz columns, as the header named them."""
    from solvers.simulate import LiveImu
    from station.capture import read_capture
    from station.cli import main

    out = tmp_path / "p4a.csv"
    with Served(LiveImu(procedure="gyro-drift", seed=4, reference=True, hold_s=1e9)) as s:
        s.imu.set_orientation("table")
        code = main(["record", "--port", s.path, "--seconds", "3", "--procedure", "gyro-drift", "--out", str(out)])
    assert code == 0
    cap = read_capture(str(out))
    assert {"ref_gx", "ref_gy", "ref_gz", "gx", "ax", "mx"} <= set(cap.columns)
    assert np.isfinite(np.asarray(cap.columns["ref_gz"], float)).mean() > 0.99
    assert np.nanstd(np.asarray(cap.columns["ref_gz"], float)) > 0.01  # the rate table moves it (rows before
    # the header came are read without its channels: a reader learns them from it)


def test_p4_reference_imu_over_a_real_pty(tmp_path):
    from solvers.simulate import LiveImu
    from station.sources import SerialSource

    db = str(tmp_path / "station.db")
    imu = LiveImu(procedure="gyro-drift", seed=24, rate_hz=100, hold_s=1e9, reference=True)
    with Served(imu, speed=6.0) as served:

        async def story():
            src = SerialSource(served.path)
            app = make_app(db, device=src, average_s=120.0)
            app.session.procedure = "gyro-reference"
            async with app.run_test(size=SIZE) as pilot:
                await connect(pilot, app, "ReferenceScreen")
                g = app.screen.guide
                await wait_for(pilot, lambda: "p Rate table (sim)" in screen_text(app).splitlines()[-1])
                await pilot.press("p")
                await wait_for(pilot, lambda: src.bench("driving") == "table")
                await wait_for(pilot, lambda: "rate table ON" in screen_text(app))
                await wait_for(pilot, lambda: g.status().t_s >= 60)
                await wait_for(pilot, lambda: "mounting check: |M|" in screen_text(app) and "OK" in screen_text(app))
                await wait_for(pilot, lambda: g.phase == "done")
                cal_id = await save(pilot, app)
                capture = app.screen.capture
            src.stop()
            return cal_id, capture

        cal_id, capture = asyncio.run(story())
    rec = Store(db).calibration(cal_id)
    assert rec["device_id"] == "SIM-GYR-0024"
    assert rec["procedure"] == "gyro-drift" and rec["params"]["mode"] == "reference"
    assert {"ref_gx", "ref_gy", "ref_gz"} <= set(capture.columns)
    # the unit's drift minus the reference's own, in P4's frame (x fwd, y up, z right) from
    # the simulated unit's x forward, y left, z up (as on the built-in device)
    truth = np.asarray(imu.gyro["eps"]) - imu.ref_bias
    truth_p4 = np.array([truth[0], truth[2], -truth[1]])
    err = np.abs(np.asarray(rec["params"]["drift"]) - truth_p4)
    assert np.all(err < 4 * np.asarray(rec["uncertainty"]["drift"])), err


def test_p5_ldv_over_a_real_pty(tmp_path):
    from solvers.simulate import LiveVehicle
    from station.sources import SerialSource

    db = str(tmp_path / "station.db")
    car = LiveVehicle(seed=25, rate_hz=10.0)
    with Served(car, speed=10.0) as served:

        async def story():
            src = SerialSource(served.path)
            app = make_app(db, device=src)
            app.session.procedure = "ldv"
            async with app.run_test(size=SIZE) as pilot:
                await connect(pilot, app, "LdvScreen")
                g = app.screen.guide
                await wait_for(pilot, lambda: "d Drive/stop (sim)" in screen_text(app).splitlines()[-1])
                assert src.bench("driving") is False and "vehicle parked" in screen_text(app)
                await pilot.press("d")
                await wait_for(pilot, lambda: src.bench("driving") is True)
                await wait_for(pilot, lambda: g.status().t_s >= 40)
                await wait_for(pilot, lambda: app.screen.last_status is not None and app.screen.last_status.t_s >= 40)
                assert g.status().verdict == "refused" and "ILL-CONDITIONED" in screen_text(app)
                assert "vehicle driving, straight" in screen_text(app)
                await pilot.press("t")
                await wait_for(pilot, lambda: src.bench("turning") is True)
                await wait_for(pilot, lambda: g.phase == "done")
                st = g.status()
                cal_id = await save(pilot, app)
            src.stop()
            return cal_id, st

        cal_id, st = asyncio.run(story())
    assert st.enough and st.kappa < 1e3
    rec = Store(db).calibration(cal_id)
    assert rec["procedure"] == "ldv" and rec["device_id"] == "SIM-LDV-0025"
    truth = car.truth
    for j in range(3):
        b, u = rec["params"][f"beam{j + 1}"], rec["uncertainty"][f"beam{j + 1}"]
        for key in ("alpha_deg", "beta_deg", "gamma_deg"):
            assert abs(b[key] - truth[key][j]) < 6 * u[key] + 0.05, (j, key, b[key], truth[key][j], u[key])
