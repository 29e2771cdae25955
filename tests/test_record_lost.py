"""A device lost for good, or back but silent, during `station record --seconds S` (issue 16):
the capture keeps every sample, says `complete: false` and why, and the command exits 1.
Real pseudo-terminals behind a symlink that is removed (unplug) and made again (replug)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import tty

import numpy as np
import pytest

from station.capture import read_capture
from station.device.protocol import Header, data_sentence, header_sentence
from station.device.reader import Reader
from station.device.record import record
from tests.station_run import ROOT

HDR = Header("BENCH-9", "g", "deg/s", "", 1000.0)


def _rows(a, b):
    return b"".join(data_sentence(k, 1000 * k, [k, 0, 1, 0, 0, 0, np.nan, np.nan, np.nan, 25]) for k in range(a, b))


class Bench:
    """A device on a pty behind `link`: plug, send, unplug."""

    def __init__(self, link: str):
        self.link = link
        self.fds = None

    def plug(self):
        m, s = os.openpty()
        tty.setraw(s)
        if os.path.lexists(self.link):
            os.unlink(self.link)
        os.symlink(os.ttyname(s), self.link)
        self.fds = (m, s)

    def send(self, data: bytes):
        os.write(self.fds[0], data)

    def unplug(self):
        os.unlink(self.link)
        for fd in self.fds:
            os.close(fd)
        self.fds = None

    def close(self):
        if self.fds:
            self.unplug()


def _wait(cond, what, timeout_s=60.0):
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.01)


def _record_in_thread(link, out, seconds, reader):
    result = {}

    def go():
        result["r"] = record(link, out, seconds=seconds, reader=reader, header_timeout_s=5.0)

    th = threading.Thread(target=go)
    th.start()
    return th, result


@pytest.fixture
def bench(tmp_path):
    b = Bench(str(tmp_path / "ttyUSB-bench"))
    b.plug()
    yield b
    b.close()


def test_a_device_lost_for_good_leaves_an_incomplete_capture_with_every_sample(bench, tmp_path):
    reader = Reader(bench.link, backoff_s=0.02, backoff_max_s=0.1).start()
    out = str(tmp_path / "lost.csv")
    th, result = _record_in_thread(bench.link, out, 3.0, reader)
    _wait(lambda: reader.stats().connected, "the connection")
    bench.send(header_sentence(HDR) + _rows(0, 150))
    _wait(lambda: reader.stats().samples >= 150, "the samples")
    bench.unplug()  # and it never comes back
    th.join(30)
    reader.stop()
    r = result["r"]
    assert "device lost" in r.incomplete and "never came back" in r.incomplete
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and "device lost" in cap.meta["incomplete"]
    assert float(cap.meta["last_data_s"]) < 3.0
    np.testing.assert_array_equal(cap.columns["ax"], np.r_[0:150])  # nothing lost that was sent


def test_a_device_that_comes_back_silent_is_said_so(bench, tmp_path):
    reader = Reader(bench.link, backoff_s=0.02, backoff_max_s=0.1).start()
    out = str(tmp_path / "silent.csv")
    th, result = _record_in_thread(bench.link, out, 4.0, reader)
    _wait(lambda: reader.stats().connected, "the connection")
    bench.send(header_sentence(HDR) + _rows(0, 100))
    _wait(lambda: reader.stats().samples >= 100, "the samples")
    bench.unplug()
    _wait(lambda: not reader.stats().connected, "the unplug to be seen")
    bench.plug()  # back, but it sends nothing
    _wait(lambda: reader.stats().connected and reader.stats().reconnects >= 1, "the reconnection")
    th.join(30)
    reader.stop()
    r = result["r"]
    assert "came back silent" in r.incomplete
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and "came back silent" in cap.meta["incomplete"]
    assert cap.n_rows == 100


def test_a_recording_that_runs_to_its_end_is_complete(bench, tmp_path):
    reader = Reader(bench.link, backoff_s=0.02, backoff_max_s=0.1).start()
    out = str(tmp_path / "ok.csv")
    stop_feeding = threading.Event()

    def feed():
        _wait(lambda: reader.stats().connected, "the connection")
        bench.send(header_sentence(HDR))
        k = 0
        while not stop_feeding.is_set():
            bench.send(_rows(k, k + 20))
            k += 20
            time.sleep(0.02)

    feeder = threading.Thread(target=feed)
    feeder.start()
    th, result = _record_in_thread(bench.link, out, 2.5, reader)
    th.join(30)
    stop_feeding.set()
    feeder.join(10)
    reader.stop()
    assert result["r"].incomplete == ""
    assert read_capture(out).meta["complete"] == "true"


def test_record_command_exits_1_when_the_device_is_lost(bench, tmp_path):
    out = tmp_path / "cli.csv"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "record", "--port", bench.link, "--seconds", "6", "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    tty_name = os.ttyname(bench.fds[1])

    def has_port_open():  # the recorder opened the port (opening flushes what was sent before)
        try:
            return any(
                os.readlink(f"/proc/{proc.pid}/fd/{fd}") == tty_name for fd in os.listdir(f"/proc/{proc.pid}/fd")
            )
        except OSError:
            return False

    _wait(has_port_open, "the recorder to open the port", timeout_s=60)
    bench.send(header_sentence(HDR))
    k = 0
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:  # about a second of data, then gone for good
        bench.send(_rows(k, k + 20))
        k += 20
        time.sleep(0.02)
    bench.unplug()
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 1, stderr
    assert "INCOMPLETE: device lost" in stdout
    assert "complete: false" in stderr
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and cap.n_rows > 0


@pytest.mark.parametrize("then", ["silent", "unplugged"])
def test_a_device_that_stops_while_the_header_is_awaited_is_timed_by_its_last_row(bench, tmp_path, then):
    """A device whose header the recorder missed (sent at power-up only) sends rows, then goes
    silent or is unplugged while the recorder still waits for a header (3.5 s here). The rows
    taken after the wait used to count as just arrived: 0.5 s of silence at the end, so a
    recording silent for 3.5 of its 4 s was `complete: true`, and a lost one 'lost 3.5 s in'."""
    reader = Reader(bench.link, backoff_s=0.02, backoff_max_s=0.1).start()
    out = str(tmp_path / f"{then}.csv")
    result = {}

    def go():
        result["r"] = record(bench.link, out, seconds=4.0, reader=reader, header_timeout_s=3.5)

    th = threading.Thread(target=go)
    th.start()
    _wait(lambda: reader.stats().connected, "the connection")
    bench.send(_rows(0, 100))  # no header
    _wait(lambda: reader.stats().samples >= 100, "the samples")
    if then == "unplugged":
        bench.unplug()
    th.join(30)
    reader.stop()
    r = result["r"]
    cap = read_capture(out)
    assert cap.n_rows == 100
    assert cap.meta["complete"] == "false", cap.meta
    assert ("went silent" if then == "silent" else "device lost") in r.incomplete
    assert float(cap.meta["last_data_s"]) < 3.0  # the rows came before the header wait ended
