"""The station line protocol parser: good, garbage, partial, checksum-bad and wrapping input,
with exact error and gap counts (docs/protocol.md)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from station.device.protocol import (
    SEQ_MODULO,
    TIME_MODULO,
    Ack,
    Command,
    Header,
    Restart,
    StationParser,
    Unknown,
    ack_sentence,
    checksum,
    command_sentence,
    data_sentence,
    data_sentences,
    header_sentence,
    sentence,
)

HEADER = Header("IMU-0042", "V", "deg/s", "uT", 100.0)


def row(i: int) -> list[float]:
    """Distinct, exactly representable values per sample."""
    return [i + 0.25, -i - 0.5, 9.75, 0.125 * i, -1.0, 2.0, 40.5, -3.25, 10.0, 24.5]


def stream(seqs, t0_us=0, dt_us=10_000) -> bytes:
    return b"".join(data_sentence(s, t0_us + k * dt_us, row(k)) for k, s in enumerate(seqs))


def parse(data: bytes, chunks=None):
    p = StationParser()
    events = []
    if chunks is None:
        events += p.feed(data)
    else:
        pos = 0
        for n in chunks:
            events += p.feed(data[pos : pos + n])
            pos += n
        events += p.feed(data[pos:])
    return p, events, p.take()


DOC = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"


def doc_sentences() -> list[bytes]:
    return [m.encode() for m in re.findall(r"\$ST[A-Z],[^*`\n]*\*[0-9A-F]{2}", DOC.read_text())]


def test_every_sentence_in_the_protocol_doc_is_valid():
    found = doc_sentences()
    assert len(found) == 16  # header, 4 data, 3 of version 2, 6 commands, 2 answers
    p = StationParser()
    for s in found:
        p.feed(s + b"\r\n")
    assert p.stats.parse_errors == 0 and p.stats.sentences == len(found)


def test_the_documented_worked_example():
    lines = [s + b"\r\n" for s in doc_sentences()[:5]]
    assert lines[0] == header_sentence(Header("IMU-0042", "V", "deg/s", "", 100.0))
    x = 0
    for c in b"STH,1,IMU-0042,V,deg/s,,100":
        x ^= c
    assert x == checksum(b"STH,1,IMU-0042,V,deg/s,,100") == 0x59
    p, ev, block = parse(b"".join(lines[:2]))
    assert p.stats.parse_errors == 0 and ev[0].rate_hz == 100.0 and block.t_dev_us[0] == 1_000_000
    np.testing.assert_array_equal(block.values[0, :6], [2.5012, 1.6633, 1.6621, 0.12, -0.05, 0.01])
    assert np.isnan(block.values[0, 6:9]).all() and block.values[0, 9] == 24.91
    # "much later": the wrap, and two sentences lost
    p, ev, block = parse(b"".join(lines[2:]))
    assert p.stats.parse_errors == 0 and p.stats.gaps == 2 and p.stats.gap_events == 1 and p.stats.restarts == 0
    np.testing.assert_array_equal(block.seq, [65535, 0, 3])
    assert np.diff(block.t_dev_us).tolist() == [10_000.0, 30_000.0]


def test_the_documented_version_2_example():
    """The reference-IMU example: three channels named in the header, their values after
    temp_c; the vehicle's header; the same bytes read as version 1 lose only the channels."""
    v2 = [s + b"\r\n" for s in doc_sentences()[5:8]]
    assert v2[0] == header_sentence(
        Header("SIM-GYR-0024", "V", "rad/s", "uT", 100.0, channels=("ref_gx", "ref_gy", "ref_gz"))
    )
    p, ev, block = parse(b"".join(v2[:2]))
    assert p.stats.parse_errors == 0 and ev[0].version == 2 and ev[0].channels == ("ref_gx", "ref_gy", "ref_gz")
    np.testing.assert_array_equal(block.values[0, 3:6], [0.00021, -0.00005, 0.05012])
    assert [block.extra[k][0] for k in ("ref_gx", "ref_gy", "ref_gz")] == [0.00019, -0.00004, 0.05009]
    p, ev, _ = parse(v2[2])
    assert ev[0].channels == ("vl1", "vl2", "vl3", "vx", "vy", "vz") and ev[0].accel_unit == ev[0].mag_unit == ""
    one = sentence(*v2[0][1:].split(b"*")[0].decode().replace("STH,2,", "STH,1,").split(","))
    p, ev, block = parse(one + v2[1])
    assert p.stats.parse_errors == 0 and ev[0].channels == () and block.extra == {} and block.values[0, 9] == 24.02
    # a channel no version knows, or one named twice: the header is malformed
    for bad in ("STH,2,X,V,,,100,ref_gx,wind", "STH,2,X,V,,,100,vl1,vl1"):
        p, ev, _ = parse(sentence(*bad.split(",")))
        assert ev == [] and p.stats.errors["malformed"] == 1


def test_a_host_that_joins_a_running_version_2_stream_keeps_the_extra_channels():
    """Rows that arrive before the first header (the host connected mid-stream) carry their
    extra values; the parser holds them until the header names them, whichever way the
    bytes are cut and however often the host takes samples meanwhile."""
    h = Header("SIM-GYR-0024", "V", "rad/s", "uT", 100.0, version=2, channels=("ref_gx", "ref_gy", "ref_gz"))
    rows = [row(k) + [0.001 * k, -0.002 * k, 0.5 + k] for k in range(8)]
    data = b"".join(data_sentence(k, 10_000 * k, rows[k]) for k in range(5)) + header_sentence(h)
    data += b"".join(data_sentence(k, 10_000 * k, rows[k]) for k in range(5, 8))
    p = StationParser()
    blocks = []
    for i in range(0, len(data), 37):
        p.feed(data[i : i + 37])
        blocks.append(p.take())
    block = type(blocks[-1]).concat([b for b in blocks if b is not None])
    assert p.stats.parse_errors == 0 and len(block) == 8
    np.testing.assert_array_equal(block.extra["ref_gz"], [0.5 + k for k in range(8)])
    np.testing.assert_array_equal(block.extra["ref_gx"], [0.001 * k for k in range(8)])
    # a version-1 device that never sends a header: its rows are not held
    p, _, block = parse(stream(range(3)))
    assert block is not None and len(block) == 3 and block.extra == {}


def test_the_documented_arduino_sentences_parse():
    """The sketch's payloads, built the way its snprintf builds them."""
    text = DOC.read_text()
    assert '"STD,%u,%lu,%s,%s,%s,,,,,,,"' in text and '"STH,1,ARDU-01,V,,,100"' in text
    data = sentence("STH", 1, "ARDU-01", "V", "", "", 100)
    data += b"".join(
        b"$%s*%02X\r\n" % (pl, checksum(pl))
        for pl in (b"STD,%d,%d,%s,%s,%s,,,,,,," % (k, 10_000 * k, b"2.5012", b"1.6633", b"1.6621") for k in range(3))
    )
    p, ev, block = parse(data)
    assert p.stats.parse_errors == 0 and len(block) == 3 and ev[0].gyro_unit == "" and ev[0].accel_unit == "V"
    assert np.isnan(block.values[:, 3:10]).all()


def test_good_stream_in_any_chunking_gives_the_same_samples():
    data = header_sentence(HEADER) + stream(range(50))
    rng = np.random.default_rng(1)
    whole, ev, block = parse(data)
    assert ev == [Header("IMU-0042", "V", "deg/s", "uT", 100.0, 1, 0)]
    assert len(block) == 50 and whole.stats.parse_errors == 0 and whole.stats.gaps == 0
    np.testing.assert_array_equal(block.values, np.array([row(k) for k in range(50)]))
    np.testing.assert_array_equal(block.t_dev_us, np.arange(50) * 10_000.0)
    for _ in range(5):
        cuts = rng.integers(1, 40, size=200)
        p, _, b = parse(data, cuts)
        np.testing.assert_array_equal(b.values, block.values)
        assert p.stats.parse_errors == 0
    p, _, b = parse(data, [1] * len(data))  # byte by byte
    np.testing.assert_array_equal(b.values, block.values)


def test_garbage_partial_and_bad_sentences_are_counted_by_kind():
    good = [data_sentence(k, k * 1000, row(k)) for k in range(12)]
    bad_cs = bytearray(good[3])
    bad_cs[8] ^= 0x01  # one flipped bit in the payload
    no_star = good[4].replace(b"*", b"")
    bad_hex = good[5][:-4] + b"ZZ\r\n"
    few = sentence("STD", 6, 6000, 1, 2, 3)
    not_number = sentence("STD", 7, 7000, "abc", *([1] * 9))
    seq_range = sentence("STD", 70000, 8000, *([1] * 10))
    data = b"".join(
        [
            header_sentence(HEADER),
            good[0],
            good[1],
            b"hello there\r\n",  # noise (a line without $)
            b"\x00\xff\x13" + good[2],  # noise in front: noise +1, sample kept
            bytes(bad_cs),  # checksum
            no_star,  # malformed
            bad_hex,  # malformed
            few,  # malformed
            not_number,  # malformed
            seq_range,  # malformed
            b"x" * 300,  # too long, no line end ...
            good[9],  # ... then a sentence: kept
            good[10],
            good[11],
        ]
    )
    p, ev, block = parse(data, [7] * 400)
    assert p.stats.errors == {"checksum": 1, "malformed": 5, "too_long": 1, "noise": 2}
    assert p.stats.parse_errors == 9
    np.testing.assert_array_equal(block.seq, [0, 1, 2, 9, 10, 11])
    # seq 2 -> 9 skipped 3..8: six samples missed, one gap
    assert p.stats.gaps == 6 and p.stats.gap_events == 1
    np.testing.assert_array_equal(block.values[3], row(9))


def test_leading_fragment_of_a_stream_is_not_an_error():
    data = header_sentence(HEADER) + stream(range(3))
    p, _, block = parse(data[17:])  # opened in the middle of the header
    assert p.stats.parse_errors == 0 and len(block) == 3
    p.reset_stream()
    p.feed(b"0,1,2*44\r\n")  # a reconnect: the tail of a line again
    assert p.stats.parse_errors == 0


def test_counters_wrap_without_gaps():
    seqs = [(SEQ_MODULO - 5 + k) % SEQ_MODULO for k in range(10)]
    t0 = TIME_MODULO - 25_000
    data = b"".join(data_sentence(s, (t0 + 10_000 * k) % TIME_MODULO, row(k)) for k, s in enumerate(seqs))
    p, ev, block = parse(data)
    assert p.stats.gaps == 0 and p.stats.restarts == 0 and ev == []
    np.testing.assert_array_equal(block.seq, seqs)
    np.testing.assert_array_equal(np.diff(block.t_dev_us), np.full(9, 10_000.0))
    assert block.t_dev_us[0] == t0


def test_gap_across_the_wrap_and_duplicates():
    seqs = [65533, 65534, 2, 2, 3]  # 65535, 0, 1 missed; 2 repeated
    p, _, block = parse(stream(seqs))
    assert p.stats.gaps == 3 and p.stats.gap_events == 1 and p.stats.duplicates == 1
    np.testing.assert_array_equal(block.seq, [65533, 65534, 2, 3])


def test_device_restart_is_an_event_not_a_gap():
    before = stream(range(100, 105), t0_us=5_000_000)
    after = header_sentence(HEADER) + stream(range(0, 3), t0_us=0)
    p, ev, block = parse(before + after)
    assert p.stats.restarts == 1 and p.stats.gaps == 0
    assert [type(e) for e in ev] == [Header, Restart] and ev[1].at_sample == 5
    assert block.t_dev_us[5] == 0.0
    # a clock going backwards without a header is a restart too
    p, ev, _ = parse(stream([1, 2], t0_us=9_000_000) + data_sentence(3, 10, row(0)))
    assert p.stats.restarts == 1 and p.stats.gaps == 0


def test_empty_nan_and_inf_fields_are_missing_values():
    s = sentence("STD", 0, 0, 1, 2, 3, "", "", "", "nan", "inf", "-inf", 25)
    p, _, block = parse(s)
    v = block.values[0]
    assert v[:3].tolist() == [1.0, 2.0, 3.0] and math.isnan(v[3]) and np.isnan(v[6:9]).all() and v[9] == 25.0
    assert p.stats.parse_errors == 0


def test_commands_acks_and_unknown_sentences():
    data = (
        command_sentence("orient", "x_up")
        + command_sentence("TEMP", 30.5)
        + ack_sentence("ORIENT", True, "x_up")
        + ack_sentence("RATE", False, "rate must be 0.1..100000 Hz")
        + sentence("XYZ", 1, 2)
        + command_sentence("HDR")
    )
    p, ev, block = parse(data)
    assert block is None and p.stats.parse_errors == 0 and p.stats.unknown == 1
    assert ev == [
        Command("ORIENT", ("x_up",)),
        Command("TEMP", ("30.5",)),
        Ack("ORIENT", True, "x_up"),
        Ack("RATE", False, "rate must be 0.1..100000 Hz"),
        Unknown(("XYZ", "1", "2")),
        Command("HDR", ()),
    ]


def test_block_encoder_matches_single_sentences():
    vals = np.array([row(k) for k in range(4)])
    vals[2, 6:9] = np.nan
    one = b"".join(data_sentence(65534 + k, 10 * k, vals[k]) for k in range(4))
    assert data_sentences(65534, 10 * np.arange(4), vals) == one


junk = st.binary(max_size=400)


@settings(max_examples=150, deadline=None)
@given(st.lists(junk, min_size=12, max_size=12), st.lists(st.integers(1, 64), max_size=60))
def test_any_junk_before_sentences_never_loses_them(junks, cuts):
    """Junk (any bytes, any length) in front of each sentence: every sentence still parses,
    whatever the chunking; the parser never raises."""
    data = b"".join(j + data_sentence(k, 1000 * k, row(k)) for k, j in enumerate(junks))
    p, _, block = parse(data, cuts)
    np.testing.assert_array_equal(block.seq, np.arange(12))
    np.testing.assert_array_equal(block.values, np.array([row(k) for k in range(12)]))
    assert p.stats.gaps == 0


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=3000))
def test_random_bytes_never_raise(data):
    p = StationParser()
    p.feed(data)
    p.take()
    assert p.stats.bytes == len(data)


@pytest.mark.parametrize(
    "line,kind",
    [
        (b"$STD,1,2*\r\n", "malformed"),
        (b"$*00\r\n", "malformed"),
        (b"$STH,1*%02X\r\n" % checksum(b"STH,1"), "malformed"),
        (b"$STD,\xff\xfe*%02X\r\n" % checksum(b"STD,\xff\xfe"), "malformed"),
        (b"$STA,ORIENT,MAYBE*%02X\r\n" % checksum(b"STA,ORIENT,MAYBE"), "malformed"),
    ],
)
def test_single_bad_lines(line, kind):
    p = StationParser()
    p.feed(data_sentence(0, 0, row(0)) + line)
    assert p.stats.errors[kind] == 1 and p.stats.parse_errors == 1
