"""`station sim-device` and `station record` end to end on real pseudo-terminals: the capture
reads back, gaps are marked, a stopped or killed recording leaves nothing silently broken."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from station.capture import read_capture
from station.device.protocol import Header, data_sentence, header_sentence
from station.device.reader import Batch, Reader
from station.device.record import RecordError, record
from tests.station_run import popen_station, sim_device, wait_for_rows

ROOT = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def raw_pty():
    """(master fd, slave's path) of a fresh pseudo-terminal in raw mode, both ends closed after."""
    m, s = os.openpty()
    tty.setraw(s)
    try:
        yield m, os.ttyname(s)
    finally:
        os.close(m)
        os.close(s)


@pytest.fixture(scope="module")
def sim_path():
    """One `station sim-device` (500 Hz, seed 7) for the module's recordings."""
    with sim_device("--rate", "500", "--seed", "7") as sim:
        yield sim.port
    assert sim.returncode == 0, sim.stderr  # a clean exit on SIGINT
    assert "samples sent" in sim.stderr


def test_record_from_sim_device_reads_back(tmp_path):
    """A clean read-back: every sample the device sent, in order, none lost. Its own device with
    `--buffer-s 30`: with the default 0.5 s the simulated UART drops what waits whenever the
    `record` process is not scheduled for half a second (a loaded 2-core machine did that), and
    the test failed on the scheduler, not on the station."""
    with sim_device("--rate", "500", "--seed", "7", "--buffer-s", "30") as sim:
        out = tmp_path / "cap.csv"
        rec = popen_station(
            "record",
            "--port",
            sim.port,
            "--seconds",
            "1.5",
            "--out",
            str(out),
            "--procedure",
            "accel-tabletop",
            "--meta",
            "latitude_deg=39.98",
        )
        stdout, stderr = rec.communicate(timeout=60)
    assert sim.returncode == 0, sim.stderr
    sent = re.search(r"(\d+) samples sent, (\d+) dropped", sim.stderr)
    assert sent and sent[2] == "0", sim.stderr  # the device discarded nothing
    assert rec.returncode == 0, stderr
    assert "recorded" in stdout and stderr == ""
    cap = read_capture(out)
    m = cap.meta
    assert m["device"] == "SIM-ACC-0007" and m["procedure"] == "accel-tabletop"
    assert (m["accel_unit"], m["gyro_unit"], m["mag_unit"]) == ("V", "rad/s", "uT")
    assert m["gaps"] == "0" and m["parse_errors"] == "0" and m["dropped"] == "0" and m["complete"] == "true"
    assert m["sample_rate_hz"] == "500" and m["segments"] == "1" and m["latitude_deg"] == "39.98"
    assert list(cap.columns) == ["t", "segment", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c"]
    # 1.5 s at 500 Hz (at least 1 s of it on a loaded machine), plus what the device had queued
    # before the port was opened; never more than the device sent
    assert 500 <= cap.n_rows <= int(sent[1]) and int(m["samples"]) == cap.n_rows
    np.testing.assert_allclose(np.diff(cap.columns["t"]), 0.002, atol=1e-9)  # no sample lost
    assert np.all(cap.columns["segment"] == 0)
    assert not list(tmp_path.glob("*.partial")) and not list(tmp_path.glob(".*tmp"))


def _wait_for(cond, what: str, timeout_s: float = 60.0) -> None:
    """Poll `cond` until true: conditions, not fixed sleeps (a loaded machine schedules late)."""
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.01)


@pytest.mark.parametrize("buffer_s", [None, 30.0], ids=["default-0.5s", "30s"])
def test_a_reader_stalled_past_the_device_buffer_sees_a_gap_and_within_it_loses_nothing(tmp_path, buffer_s):
    """The simulated UART holds `max_pending_s` of output (`sim-device --buffer-s`, default
    0.5 s) beyond what the pty takes, for a host that does not read. `station record` is
    stopped (SIGSTOP: what a starved process looks like to the device): with the default, until
    the device discards what waits, and the capture says how many samples it missed; with a
    30 s buffer, for 5 s of samples, and every sample arrives, in order. Both wait on the
    device's own counters, so neither depends on how the machine schedules them."""
    from solvers.simulate import LiveImu
    from station.device.simdevice import SimDevice

    kw = {} if buffer_s is None else {"max_pending_s": buffer_s}
    dev = SimDevice(LiveImu(procedure="accel-tabletop", seed=5, rate_hz=500.0), **kw)
    out = tmp_path / "s.csv"
    partial = Path(str(out) + ".partial")

    def rows() -> int:
        return partial.read_bytes().count(b"\n") if partial.exists() else 0

    stop = threading.Event()
    with dev:
        th = threading.Thread(target=dev.run, args=(stop,), daemon=True)
        th.start()
        rec = popen_station("record", "--port", dev.path, "--out", str(out))
        try:
            _wait_for(lambda: rows() > 100, "the first rows")
            rec.send_signal(signal.SIGSTOP)
            at_stop, dropped_before = dev.stats.samples, dev.stats.dropped  # (drops while `record` started: no gap)
            if buffer_s is None:
                _wait_for(lambda: dev.stats.dropped > dropped_before, "the device to discard what waits")
            else:  # 5 s: past the pty's own ~64 KB (about 1 s here) and the default 0.5 s
                _wait_for(lambda: dev.stats.samples - at_stop >= 2500, "5 s of samples sent to the stopped reader")
            behind = dev.stats.samples - at_stop if buffer_s else 0  # rows still to come from the stall
            rec.send_signal(signal.SIGCONT)
            at_cont = rows()
            _wait_for(lambda: rows() >= at_cont + behind + 500, "1 s of rows after the stall")  # past the stall
            rec.send_signal(signal.SIGTERM)
            stdout, stderr = rec.communicate(timeout=30)
        finally:
            rec.send_signal(signal.SIGCONT)  # never leave a stopped process behind
            if rec.poll() is None:
                rec.kill()
                rec.communicate(timeout=30)
            stop.set()
            th.join(5)
    assert rec.returncode == 0, stderr
    cap = read_capture(out)
    t = cap.columns["t"]
    if buffer_s is None:
        # the device discarded what waited (its queue, counted, and the pty's unread bytes; again
        # after the stall if the loaded machine is slow to catch up): the reader saw the sequence
        # jump, and every sample of the span is either a row or counted as missed. (Not `missed >=
        # dropped`: the device goes on discarding once `record` has stopped reading for good, and on
        # a loaded machine that is hundreds of samples no capture can see: 388 gaps for 494 drops.)
        dropped, missed = dev.stats.dropped - dropped_before, int(cap.meta["gaps"])
        assert dropped > 0 and missed > 0, (cap.meta, dev.stats, dropped_before)
        assert round((t[-1] - t[0]) / 0.002) + 1 == cap.n_rows + missed and np.diff(t).max() > 0.003
        assert int(cap.meta["samples"]) == cap.n_rows
    else:
        assert cap.meta["gaps"] == "0" and dev.stats.dropped == 0, (cap.meta, dev.stats)
        np.testing.assert_allclose(np.diff(t), 0.002, atol=1e-9)  # every sample, in order
        assert cap.n_rows >= 100 + 2500 + 500


def test_sigterm_ends_a_recording_with_a_complete_capture(sim_path, tmp_path):
    path = sim_path
    out = tmp_path / "c.csv"
    rec = popen_station("record", "--port", path, "--out", str(out))
    partial = Path(str(out) + ".partial")
    wait_for_rows(partial, 3000)
    rec.send_signal(signal.SIGTERM)
    assert rec.wait(20) == 0, rec.stderr.read()
    rec.stdout.close()
    rec.stderr.close()
    cap = read_capture(out)
    assert cap.meta["complete"] == "true" and cap.n_rows > 10 and not partial.exists()


def test_an_interrupt_before_the_seconds_asked_keeps_the_rows_marked_incomplete(sim_path, tmp_path):
    """`--seconds 120` cut short by Ctrl-C: every row is kept, but the capture says it is
    shorter than asked (`complete: false`, why) and the exit status is 1, as for a device lost;
    it was kept as complete, with exit 0."""
    out = tmp_path / "c.csv"
    rec = popen_station("record", "--port", sim_path, "--seconds", "120", "--out", str(out))
    partial = Path(str(out) + ".partial")
    wait_for_rows(partial, 3000)
    rec.send_signal(signal.SIGINT)
    stdout, stderr = rec.communicate(timeout=20)
    assert rec.returncode == 1, stderr
    assert "INCOMPLETE: interrupted" in stdout and "of the 120" not in stdout
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and cap.meta["incomplete"].startswith("interrupted ")
    assert "120 s asked for" in cap.meta["incomplete"] and cap.n_rows > 10 and not partial.exists()


def test_a_killed_recording_leaves_a_partial_capture_that_recovers(sim_path, tmp_path):
    path = sim_path
    out = tmp_path / "k.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", path, "--out", str(out))
    wait_for_rows(partial, 3000)
    rec.kill()
    rec.wait(10)
    rec.stdout.close()
    rec.stderr.close()
    assert not out.exists() and partial.exists()
    with open(partial, "a") as f:
        f.write("99.000000,0,2.41")  # a row cut by the kill
    fix = popen_station("record", "--recover", str(partial))
    stdout, stderr = fix.communicate(timeout=60)
    assert fix.returncode == 0, stderr
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and cap.meta["recovered"] == "true"
    assert cap.n_rows > 10 and cap.columns["t"][-1] < 99.0 and not partial.exists()


def test_sim_device_obeys_commands(tmp_path):
    """ORIENT moves the simulated unit (x_up -> x_down flips ax), bad commands get ERR."""
    import threading

    from solvers.simulate import LiveImu
    from station.device.simdevice import SimDevice

    dev = SimDevice(LiveImu(procedure="accel-tabletop", seed=1, rate_hz=200.0))
    stop = threading.Event()
    with dev:
        th = threading.Thread(target=dev.run, args=(stop,), daemon=True)
        th.start()
        try:
            with Reader(dev.path) as r:
                assert r.wait_header(60.0).device_id == "SIM-ACC-0001"
                first, end = [], time.monotonic() + 60.0
                while sum(map(len, first)) < 40 and time.monotonic() < end:  # 0.2 s of samples
                    time.sleep(0.05)
                    if (b := r.drain()) is not None:
                        first.append(b)
                before = Batch.concat(first).column("ax").mean()
                assert r.command("ORIENT", "x_down") and r.command("ORIENT", "sideways")
                assert r.command("AUTO", "compass") and r.command("TEMP", "hot") and r.command("RATE", "400")
                # the move takes 2.5 s of device time; wait for it (up to 60 s on a busy machine)
                got, end = [], time.monotonic() + 60.0
                while time.monotonic() < end:
                    time.sleep(0.1)
                    if (b := r.drain()) is not None:
                        got.append(b)
                    if len(got) > 5 and Batch.concat(got).column("ax")[-20:].mean() < before - 1.5:
                        break
                b = Batch.concat(got)
                acks = list(r.acks)
        finally:
            stop.set()
            th.join(5)
    assert [(a.verb, a.ok) for a in acks] == [
        ("ORIENT", True),
        ("ORIENT", False),
        ("AUTO", False),
        ("TEMP", False),
        ("RATE", True),
    ]
    assert "sideways" in acks[1].text and "accel-tabletop" in acks[2].text
    # 0.0855 V per m/s^2 times 2 g: x_up -> x_down lowers ax by ~1.7 V (noise 0.001 V)
    assert b.column("ax")[-20:].mean() < before - 1.5
    assert np.median(np.diff(b.t_s[-50:])) == pytest.approx(1 / 400, abs=1e-6)


def test_recording_across_an_unplug_marks_the_gap_in_the_capture(tmp_path):
    link = str(tmp_path / "ttyACM-bench")
    hdr = Header("BENCH-1", "g", "deg/s", "", 1000.0)

    def plug():
        m, s = os.openpty()
        tty.setraw(s)
        if os.path.lexists(link):
            os.unlink(link)
        os.symlink(os.ttyname(s), link)
        return m, s

    def rows(a, b):
        return b"".join(data_sentence(k, 1000 * k, [k, 0, 1, 0, 0, 0, np.nan, np.nan, np.nan, 25]) for k in range(a, b))

    m, s = plug()
    stop = threading.Event()
    result = {}
    reader = Reader(link, backoff_s=0.02, backoff_max_s=0.1).start()

    def go():
        result["r"] = record(link, str(tmp_path / "u.csv"), stop=stop, reader=reader, header_timeout_s=5.0)

    def wait_for(cond, what, timeout_s=60.0):
        # conditions, not fixed sleeps: a loaded CI machine schedules the reader late
        end = time.monotonic() + timeout_s
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            time.sleep(0.01)

    th = threading.Thread(target=go)
    th.start()
    wait_for(lambda: reader.stats().connected, "the first connection")
    os.write(m, header_sentence(hdr) + rows(0, 100))
    wait_for(lambda: reader.stats().samples >= 100, "the first 100 samples")
    os.unlink(link)
    os.close(m)
    os.close(s)
    time.sleep(0.3)
    m, s = plug()
    wait_for(lambda: reader.stats().connected, "the reconnection")
    os.write(m, header_sentence(hdr) + rows(130, 200))
    wait_for(lambda: reader.stats().samples >= 170, "the samples after the reconnect")
    stop.set()
    th.join(10)
    reader.stop()
    os.close(m)
    os.close(s)
    cap = read_capture(tmp_path / "u.csv")
    assert list(cap.columns) == ["t", "segment", "ax", "ay", "az", "gx", "gy", "gz", "temp_c"]  # no magnetometer
    assert cap.n_rows == 170 and cap.meta["gaps"] == "30" and cap.meta["reconnects"] == "1"
    np.testing.assert_array_equal(cap.columns["ax"], np.r_[0:100, 130:200])
    np.testing.assert_array_equal(cap.columns["segment"], np.r_[[0] * 100, [1] * 70])
    assert (
        cap.meta["gap_1"].startswith("segment 1 reconnect: t 0.099000 -> 0.130000 s")
        and "missed 30" in cap.meta["gap_1"]
    )


def test_no_samples_is_an_error_and_leaves_no_file(tmp_path):
    with (
        raw_pty() as (_, port),
        pytest.raises(RecordError, match="no samples received in .* s: the device sent nothing"),
    ):
        record(port, str(tmp_path / "e.csv"), seconds=0.3, header_timeout_s=0.2)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("protocol", "says"),
    [("station", "no station sample among them"), ("mavlink", "no mavlink sample among them")],
)
def test_bytes_that_hold_no_sample_are_said_with_the_likely_cause(tmp_path, protocol, says):
    """A device read at the wrong baud rate gives bytes that parse as nothing: the refusal said
    'no samples received', as for a device that sends nothing at all. Now it says how many
    bytes came, what the parser made of them and which options to check."""
    m, s = os.openpty()
    tty.setraw(s)
    rng = np.random.default_rng(400015)
    stop = threading.Event()
    reader = Reader(os.ttyname(s)).start()

    def noise():  # what 115200-baud text looks like when read at another rate, roughly
        while not stop.is_set():
            os.write(m, rng.integers(0, 256, 512, dtype=np.uint8).tobytes())
            stop.wait(0.01)

    th = threading.Thread(target=noise)
    try:
        th.start()
        with pytest.raises(RecordError) as err:
            record(os.ttyname(s), str(tmp_path / "e.csv"), seconds=1.0, header_timeout_s=0.2, protocol=protocol,
                   reader=reader)  # fmt: skip
    finally:
        stop.set()
        th.join(10)
        reader.stop()
        os.close(m)
        os.close(s)
    text = str(err.value)
    assert "no samples received" in text and says in text and "bytes came" in text, text
    assert "--baud (this read at 115200) or --protocol?" in text
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "args,message",
    [
        (
            ["record", "--port", "/dev/nonexistent-tty", "--out", "x.csv", "--seconds", "1"],
            "/dev/nonexistent-tty: cannot open",
        ),
        (["record", "--out", "x.csv"], "--port is required"),
        (["record", "--port", "loop://", "--out", "x.csv", "--mavlink-message", "GPS_RAW"], "GPS_RAW"),
        (["sim-device", "--effect", "warp_drive=3"], "warp_drive"),
        (["sim-device", "--effect", "temperature_bias=big"], "'big' is not a number"),
        (["sim-device", "--rate", "0"], "--rate 0"),
        (["sim-device", "--buffer-s", "0"], "--buffer-s must be a positive number of seconds, got 0"),
        (["sim-device", "--buffer-s", "nan"], "--buffer-s must be a positive number of seconds, got nan"),
    ],
)
def test_bad_arguments_get_one_line_and_exit_2(args, message, tmp_path, monkeypatch, capsys):
    from station.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_bad_metadata_is_refused_before_recording(tmp_path, capsys):
    from station.cli import main

    with raw_pty() as (_, port):
        rc = main(
            [
                "record",
                "--port",
                port,
                "--seconds",
                "1",
                "--out",
                str(tmp_path / "b.csv"),
                "--meta",
                "latitude_deg=north",
            ]
        )
    err = capsys.readouterr().err
    assert rc == 2 and "latitude_deg" in err and "'north' is not a number" in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_ports_lists_or_says_no_ports():
    p = subprocess.run([sys.executable, "-m", "station", "ports"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    from serial.tools import list_ports

    n = len(list_ports.comports())
    assert p.returncode == 0
    assert p.stdout.strip() == "no ports" if n == 0 else len(p.stdout.strip().splitlines()) == n


def test_a_different_device_on_the_port_ends_the_recording_keeping_what_came_before(tmp_path):
    warnings = []
    with raw_pty() as (m, port):
        reader = Reader(port).start()
        a, b = Header("UNIT-A", "g", "", "", 100.0), Header("UNIT-B", "g", "", "", 100.0)
        rows = b"".join(data_sentence(k, 10_000 * k, [k, 0, 1] + [np.nan] * 6 + [20]) for k in range(50))
        timer = threading.Timer(0.3, lambda: os.write(m, header_sentence(a) + rows))
        timer2 = threading.Timer(0.8, lambda: os.write(m, header_sentence(b) + data_sentence(0, 0, [9] * 10)))
        timer.start()
        timer2.start()
        res = record(port, str(tmp_path / "d.csv"), reader=reader, seconds=10, warn=warnings.append)
        reader.stop()
    cap = read_capture(tmp_path / "d.csv")
    assert res.stopped_because == "device changed" and "UNIT-A" in warnings[0] and "UNIT-B" in warnings[0]
    assert (
        cap.meta["device"] == "UNIT-A"
        and cap.n_rows == 50
        and list(cap.columns) == ["t", "segment", "ax", "ay", "az", "temp_c"]
    )
    # stopped before the 10 s asked for: not complete (it was `complete: true`, exit 0, in a
    # new user's `--seconds 12` stopped at 4.05 s), as an interrupt or a lost device is
    assert cap.meta["complete"] == "false" and cap.meta["incomplete"].startswith("device changed ")
    assert res.incomplete.endswith("into the 10 s asked for"), res.incomplete


def _refused_port() -> int:
    """A local TCP port nothing listens on (bound, then closed)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    ("protocol", "port", "says"),
    [
        ("station", "socket://host:99999", "port number 99999 is out of range 1-65535: expected socket://HOST:PORT"),
        ("station", "socket://localhost:", "no port number: expected socket://HOST:PORT"),
        ("station", "rfc2217://host:70000", "port number 70000 is out of range 1-65535: expected rfc2217://HOST:PORT"),
        ("station", "socket://127.0.0.1:{refused}", "cannot open: Connection refused"),
        ("station", "loop://?bad=1", "unknown option 'bad'"),
        ("station", "foo://x", "unknown URL scheme 'foo'"),
        ("station", "{tmp}/no-such-tty", "cannot open: No such file or directory"),
        ("mavlink", "udp:host:99999", "port number 99999 is out of range 1-65535: expected udp:HOST:PORT"),
        ("mavlink", "tcp:", "no port number: expected tcp:HOST:PORT"),
        ("mavlink", "tcp:127.0.0.1:{refused}", "cannot open: Connection refused"),
    ],
)
def test_a_bad_port_or_url_is_one_line_saying_what_is_wrong(tmp_path, protocol, port, says):
    """pyserial's own text reached the operator: ``socket://host:99999`` gave
    ``'debug|info|warning|error'`` (its format string failing on the bad port),
    ``loop://?bad=1`` a KeyError, ``/dev/x`` "could not open port /dev/x: [Errno 2] ...", and
    pymavlink printed "... sleeping" on stdout. Now one line: the port, what is wrong."""
    from tests.station_run import assert_one_line_refusal

    port = port.format(refused=_refused_port(), tmp=tmp_path)
    out = tmp_path / "rec.csv"
    res = subprocess.run(
        [sys.executable, "-m", "station", "record", "--protocol", protocol, "--port", port, "--seconds", "1"]
        + ["--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_one_line_refusal(res, f"station: {port}: {says}")
    assert not out.exists()
    assert "Errno" not in res.stderr and "could not open port" not in res.stderr.lower()


@pytest.mark.parametrize("spelling", ["same", "dot"])
def test_recover_into_the_partial_itself_is_refused_and_the_partial_kept(tmp_path, spelling):
    """record --recover k.csv.partial --out k.csv.partial wrote the capture over the partial,
    then removed the partial as recovered: exit 0, 'recovered', and the recording gone."""
    from tests.station_run import assert_one_line_refusal, run_station

    partial = tmp_path / "k.csv.partial"
    res = run_station("simulate", "--procedure", "gyro-drift", "--seed", "1", "--out", partial)
    assert res.returncode == 0, res.stderr
    before = partial.read_bytes()
    out = partial if spelling == "same" else tmp_path / "." / partial.name
    res = run_station("record", "--recover", partial, "--out", out)
    assert_one_line_refusal(res, "the .partial file being recovered")
    assert partial.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["k.csv.partial"]


def test_a_new_recording_does_not_replace_a_partial_not_yet_recovered(tmp_path):
    """A killed recording leaves k.csv.partial; the next `record --out k.csv` wrote its own
    rows into that name and removed it when done: the killed recording was lost without a
    word. Refused before the port is opened, the partial kept; the writer itself never
    truncates one either."""
    from station.device.record import CaptureStream
    from station.errors import InputError
    from tests.station_run import assert_one_line_refusal, run_station

    partial = tmp_path / "k.csv.partial"
    res = run_station("simulate", "--procedure", "gyro-drift", "--seed", "1", "--out", partial)
    assert res.returncode == 0, res.stderr
    before = partial.read_bytes()
    res = run_station("record", "--port", tmp_path / "no-such-port", "--seconds", "1", "--out", tmp_path / "k.csv")
    assert_one_line_refusal(res, f"{partial}: ", "record --recover")
    with pytest.raises(InputError, match="record --recover"):
        CaptureStream(str(tmp_path / "k.csv"), ["t", "ax", "ay", "az"], {"accel_unit": "V"})
    assert partial.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["k.csv.partial"]


@pytest.mark.parametrize(
    "key",
    ["complete", "incomplete", "recovered", "gaps", "gap_1", "samples", "station-capture"]
    + ["sample_rate_hz", "Sample_Rate_Hz"],  # measured; Sample_Rate_Hz=50 gave a capture inspect refused
)
def test_meta_cannot_set_what_the_recording_says_about_itself(tmp_path, key):
    """--meta incomplete=... on a recording that ran to its end gave 'complete: true' beside
    'incomplete: ...'; --meta recovered=true marked a live recording as recovered. The keys
    the recording writes about itself are refused, before the port is opened."""
    from tests.station_run import assert_one_line_refusal, run_station

    out = tmp_path / "r.csv"
    res = run_station(
        "record", "--port", tmp_path / "no-such-port", "--seconds", "1", "--meta", f"{key}=x", "--out", out
    )
    assert_one_line_refusal(res, f"--meta {key}", "the recording writes it")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("baud", ["99999999999999", "2147483648", "12000001", "0", "-5", "49", "fast", "1e6"])
def test_an_absurd_baud_rate_is_refused_with_the_range_before_anything_opens(baud, tmp_path, capsys):
    """`--baud 99999999999999` reached the serial driver and came back as "cannot open: signed
    integer is greater than maximum"; 0 and negatives said only "must be positive". Now refused
    where the arguments are read, on a real pseudo-terminal: one line naming --baud and the
    range (50, the lowest standard rate, to 12000000, what high-speed USB adapters reach),
    exit status 2, nothing written."""
    from station.cli import main

    with raw_pty() as (_, port), pytest.raises(SystemExit) as exit_:
        main(["record", "--port", port, "--seconds", "1", "--out", str(tmp_path / "b.csv"), f"--baud={baud}"])
    out, err = capsys.readouterr()
    assert exit_.value.code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert "--baud" in err and "from 50" in err and "to 12000000" in err and "signed integer" not in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("baud", ["50", "115200", "4000000", "12000000"])
def test_baud_rates_in_the_range_are_taken(baud):
    from station.commands.record import baud_arg

    assert baud_arg(baud) == int(baud)


def test_meta_in_other_letter_case_replaces_the_key_and_the_capture_reads_back(sim_path, tmp_path):
    """`--meta Device=bench-7` (or DATE=...) wrote 'Device' beside the header's 'device': the reader
    takes keys in any letter case and refused the head as one key spelled twice, so the recording
    stopped on its own .partial file; `--meta Sample_Rate_Hz=50` was not even caught and the
    finished capture was refused by `station inspect`. A --meta key replaces the one it names."""
    from tests.station_run import run_station

    out = tmp_path / "c.csv"
    res = run_station(
        "record", "--port", sim_path, "--seconds", "0.5", "--out", out,
        "--meta", "Device=bench-7", "--meta", "DATE=2026-01-02", "--meta", "Latitude_Deg=39.98",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    cap = read_capture(out)
    assert cap.meta["device"] == "bench-7" and cap.meta["date"] == "2026-01-02"
    assert "Device" not in cap.meta and "DATE" not in cap.meta
    res = run_station("inspect", out)  # the station's own command reads it
    assert res.returncode == 0 and "device:     bench-7" in res.stdout, res.stderr


def test_meta_cannot_relabel_the_unit_the_device_says(sim_path, tmp_path):
    """`--meta accel_unit=g` on a device whose header says V wrote 'accel_unit: g' over the
    device's own unit: volts calibrated as g. Refused in one line, no file left."""
    from tests.station_run import assert_one_line_refusal, run_station

    out = tmp_path / "u.csv"
    res = run_station("record", "--port", sim_path, "--seconds", "0.5", "--out", out, "--meta", "accel_unit=g")
    assert_one_line_refusal(res, "--meta accel_unit=g", "the device says accel_unit V")
    assert os.listdir(tmp_path) == []


def test_a_slow_device_gets_its_sample_rate_measured(tmp_path):
    """A 10 Hz device (the LDV bench's rate) sends one sample per 0.1 s poll; the rate was
    measured only inside batches of 3 or more, so the capture had no sample_rate_hz and
    `station record` said '? Hz'. The steps between batches count."""
    from tests.station_run import run_station

    with sim_device("--rate", "10", "--seed", "3") as sim:
        out = tmp_path / "slow.csv"
        # 4 s, not 1.5: on a loaded machine (load 9) the first rows can come a second late, and
        # one batch of one row measures no step
        res = run_station("record", "--port", sim.port, "--seconds", "4", "--out", out)
        assert res.returncode == 0, res.stderr
        assert "? Hz" not in res.stdout and ", 10 Hz)" in res.stdout, res.stdout
        assert read_capture(out).meta["sample_rate_hz"] == "10"
