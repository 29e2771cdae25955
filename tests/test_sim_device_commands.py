"""The simulated device's answers to an operator's commands typed wrong, over a real
pseudo-terminal with pyserial (docs/protocol.md section 5): each wrong command is answered
`$STA,<verb>,ERR,<why>` in one sentence the station's own parser reads, saying what the
device takes; a set point it would turn into readings the station refuses is refused.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from solvers.simulate import LiveImu
from station.device.protocol import Ack, StationParser, sentence
from station.procedures.centrifuge_guide import CentrifugeImu

serial = pytest.importorskip("serial")


class Served:
    """A SimDevice on a real pty, streaming in a thread, and pyserial on its other end."""

    def __init__(self, imu) -> None:
        from station.device.simdevice import SimDevice

        # a 30 s UART buffer: the device clock's steps are read back whole even when the
        # machine leaves this thread out for over 0.5 s (the default buffer drops, a gap)
        self.dev = SimDevice(imu, max_pending_s=30.0)
        self.path = self.dev.open()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.dev.run, args=(self.stop,), daemon=True)
        self.parser = StationParser()

    def __enter__(self):
        self.thread.start()
        self.port = serial.Serial(self.path, 115200, timeout=0.05)
        return self

    def __exit__(self, *exc):
        self.port.close()
        self.stop.set()
        self.thread.join(5)
        self.dev.close()

    def ask(self, *fields: str, timeout_s: float = 10.0) -> Ack:
        """Send `$STC,<fields>` and wait for the device's answer to that verb."""
        self.port.write(sentence("STC", *fields))
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            for ev in self.parser.feed(self.port.read(4096)):
                if isinstance(ev, Ack) and ev.verb == fields[0]:
                    return ev
        raise AssertionError(f"no answer to {fields} within {timeout_s} s (errors {self.parser.stats.errors})")


def test_a_centrifuge_setting_typed_wrong_is_answered_with_the_form_it_takes():
    """`$STC,ORIENT,x_up` to the P2 bench answered "invalid literal for int() with base 10:
    'x_up'": Python's words, not the 'k@omega' form the bench takes (nor did any document
    say it)."""
    with Served(CentrifugeImu(seed=1, rate_hz=50.0)) as dev:
        for wrong in ("x_up", "3@fast", "@", "99@1"):
            ack = dev.ask("ORIENT", wrong)
            assert not ack.ok and "k@omega" in ack.text and "1..20" in ack.text, ack
            assert "literal" not in ack.text and "convert" not in ack.text, ack
        assert dev.ask("ORIENT", "3@12.5").ok


@pytest.mark.parametrize(
    "procedure, own",
    [("compass", ["s1..s12"]), ("accel-tabletop", ["x_up", "yz_135", "xz_135"]), ("gyro-drift", ["level"])],
)
def test_an_unknown_position_is_answered_with_the_devices_own_positions(procedure, own):
    """The compass device answered an unknown position with the P1 faces only (its list, P1
    first, was cut at 120 characters before s1..s12); the P1 device's list lost its last
    positions. The answer names the device's own positions whole, in one sentence of at most
    256 bytes (the parser counts a longer one `too_long` and drops it), a long name cut short."""
    with Served(LiveImu(procedure=procedure, seed=1, rate_hz=50.0)) as dev:
        for wrong in ("sideways", "y" * 200):
            ack = dev.ask("ORIENT", wrong)
            assert not ack.ok and all(name in ack.text for name in own), ack
        assert dev.parser.stats.errors.get("too_long", 0) == 0


@pytest.mark.parametrize("set_point", ["1e308", "-300", "abc", "nan"])
def test_a_temperature_set_point_no_chamber_reaches_is_refused(set_point):
    """`$STC,TEMP,1e308` was taken: the device then streamed temp_c of 1e307, which `station
    record` wrote and `station inspect` refused ("beyond what any instrument reports");
    -300 degC (below absolute zero) was taken too; 'abc' was answered with Python's "could not
    convert string to float". A set point in range still works."""
    with Served(LiveImu(procedure="accel-tabletop", seed=1, rate_hz=50.0)) as dev:
        ack = dev.ask("TEMP", set_point)
        assert not ack.ok and "degC" in ack.text and "convert" not in ack.text, ack
        assert dev.ask("TEMP", "35").ok


@pytest.mark.parametrize("verb", ["ORIENT", "TEMP", "AUTO", "RATE"])
def test_a_known_command_without_its_argument_is_answered_with_what_it_takes(verb):
    """`$STC,ORIENT` (no position) was answered "unknown command ORIENT", as if the device did
    not know ORIENT at all (docs/protocol.md section 5 lists it); TEMP, AUTO and RATE alike. The
    answer names the argument the command takes."""
    with Served(LiveImu(procedure="accel-tabletop", seed=1, rate_hz=50.0)) as dev:
        ack = dev.ask(verb)
        assert not ack.ok and "unknown command" not in ack.text, ack
        assert ack.text.startswith(f"{verb} takes "), ack
        assert "STC" not in ack.text, ack  # a '$' or ',' in the text would be mangled on the line


@pytest.mark.parametrize("rate", ["abc", "", "nan"])
def test_a_rate_that_is_no_number_is_answered_in_the_devices_words(rate):
    """`$STC,RATE,abc` was answered with Python's "could not convert string to float: 'abc'"; it
    is answered as a rate out of range is, with the range the device takes."""
    with Served(LiveImu(procedure="accel-tabletop", seed=1, rate_hz=50.0)) as dev:
        ack = dev.ask("RATE", rate)
        assert not ack.ok and "convert" not in ack.text and "0.1..100000 Hz" in ack.text, ack
        assert dev.ask("RATE", "100").ok


@pytest.mark.parametrize("new_rate_hz", [20.0, 200.0])
def test_the_centrifuge_clock_runs_on_when_its_rate_is_changed(new_rate_hz):
    """The P2 bench stamped sample i at i / rate: `$STC,RATE,20` on a 100 Hz bench moved its
    device clock 5 times further on at once (t_device_us jumped from 1 s to 5 s between two
    consecutive samples), `$STC,RATE,200` sent it back in time, which a reader takes for a
    restart of the device (docs/protocol.md section 3). A device's clock runs on: every step
    after the change is the new period."""
    with Served(CentrifugeImu(seed=1, rate_hz=100.0)) as dev:
        t_us: list[float] = []

        def collect(until):
            t_end = time.monotonic() + 10.0
            while time.monotonic() < t_end and not until():
                dev.parser.feed(dev.port.read(4096))
                block = dev.parser.take()
                if block is not None:
                    t_us.extend(block.t_dev_us.tolist())

        collect(lambda: len(t_us) >= 20)
        assert dev.ask("RATE", f"{new_rate_hz:g}").ok
        n_before = len(t_us)
        collect(lambda: len(t_us) >= n_before + 20)
        steps = np.diff(t_us)
        assert steps.min() > 0, f"the device clock went back: {steps.min()} us"
        period_us = 1e6 / new_rate_hz
        assert np.all((np.abs(steps - 10_000) <= 1) | (np.abs(steps - period_us) <= 1)), sorted(set(steps))
        assert dev.parser.stats.restarts == 0
