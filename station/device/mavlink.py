"""MAVLink IMU input (and output for the simulated device) through pymavlink.

Messages read, and the units the station gives them (docs/protocol.md, "MAVLink"):

| message | accel | gyro | mag | temperature | time |
|---|---|---|---|---|---|
| HIGHRES_IMU | m/s^2 (as sent) | rad/s (as sent) | gauss (as sent) | degC | time_usec |
| SCALED_IMU, SCALED_IMU2, SCALED_IMU3 | mG / 1000 -> `g` | mrad/s / 1000 -> `rad/s` | mgauss / 1000 -> `gauss` | cdegC / 100 | time_boot_ms |
| RAW_IMU | mG / 1000 -> `g` | mrad/s / 1000 -> `rad/s` | mgauss / 1000 -> `gauss` | cdegC / 100 | time_usec |

RAW_IMU: the MAVLink spec says "raw values", but ArduPilot, the firmware that streams it,
sends its first IMU already corrected in mG, mrad/s and milligauss
(GCS_MAVLINK::send_raw_imu: `accel * 1000 / GRAVITY_MSS`, `gyro * 1000`, the compass field
in mGauss). It is read in those units unless the sender's HEARTBEAT, seen before the
stream was chosen, names another autopilot: then it stays in `counts`.

A temperature of exactly 0 in SCALED_IMU*/RAW_IMU means "no sensor" (MAVLink spec) and
becomes NaN. HIGHRES_IMU's `fields_updated` is not used: every field is kept.

One stream is recorded: the message type (and HIGHRES_IMU/RAW_IMU `id`) named by
`source`, or else the first IMU message seen. Gaps are counted from the MAVLink packet
sequence number of that stream's system/component, over every message it sends: `gaps`
counts lost packets of any type, an upper bound on lost IMU samples. A frame is a
duplicate only when its sequence number, type and payload all repeat the previous
frame's: a sender whose frames all carry the same sequence number (pymavlink's `pack()`
without `send()`) loses nothing, since its IMU timestamps advance.
"""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
from pymavlink.dialects.v20 import all as mavlink2

from station.device.protocol import (
    ERROR_KINDS,
    Header,
    ParseStats,
    Restart,
    SampleBlock,
    Unknown,
)

# type -> (accel unit, gyro unit, mag unit, value factor, temperature factor, time factor to us)
IMU_MESSAGES: dict[str, tuple[str, str, str, float, float, float]] = {
    "HIGHRES_IMU": ("m/s^2", "rad/s", "gauss", 1.0, 1.0, 1.0),
    "SCALED_IMU": ("g", "rad/s", "gauss", 1e-3, 1e-2, 1e3),
    "SCALED_IMU2": ("g", "rad/s", "gauss", 1e-3, 1e-2, 1e3),
    "SCALED_IMU3": ("g", "rad/s", "gauss", 1e-3, 1e-2, 1e3),
    "RAW_IMU": ("g", "rad/s", "gauss", 1e-3, 1e-2, 1.0),  # ArduPilot's units (see above)
}
RAW_IMU_COUNTS = ("counts", "counts", "counts", 1.0, 1e-2, 1.0)  # RAW_IMU from another autopilot
_TIME_BOOT_MS_MODULO_US = (1 << 32) * 1000  # time_boot_ms is uint32
HIGHRES_FIELDS_ALL = 0x1FFF  # acc, gyro, mag, pressures, pressure_alt, temperature


def _instance(msg) -> int:
    return int(getattr(msg, "id", 0) or 0)


def parse_source(source: str | None) -> tuple[str | None, int | None]:
    """'HIGHRES_IMU', 'RAW_IMU:1', None -> (type, instance id or None)."""
    if not source:
        return None, None
    name, _, inst = source.upper().partition(":")
    if name not in IMU_MESSAGES:
        raise ValueError(f"unknown MAVLink IMU message {name!r} (one of {', '.join(IMU_MESSAGES)})")
    return name, (int(inst) if inst else None)


class MavlinkParser:
    """Incremental MAVLink (1 and 2) parser with the same interface as StationParser.

        `feed(chunk)` returns events (a synthetic Header when the stream is chosen,
        Restart, Unknown for nothing); samples accumulate until `take()`. Errors by kind:
        `noise` (bytes before a frame start), `checksum` (bad CRC), `malformed` (other
        undecodable frames). Valid messages of other types count as `unknown`. Bytes before
    the first valid frame of a stream (or after `reset_stream()`) are not counted.
    """

    def __init__(self, source: str | None = None, request_hz: float | None = None) -> None:
        self.stats = ParseStats()
        self.header: Header | None = None
        self.want_type, self.want_id = parse_source(source)
        self.link = BoardLink(self.want_type, request_hz) if request_hz else None
        self.source: str | None = None  # e.g. 'HIGHRES_IMU:0' once chosen
        self.system: tuple[int, int] | None = None  # (sysid, compid) of the chosen stream
        self.heartbeats: dict[tuple[int, int], int] = {}
        self.autopilots: dict[tuple[int, int], int] = {}  # MAV_AUTOPILOT_* from each sender's HEARTBEAT
        self._units = None  # the chosen stream's IMU_MESSAGES row
        self._last_frame: tuple | None = None  # (seq, type, payload) of the stream's previous frame
        self._new_mav()
        self._rows: list[list[float]] = []
        self._last_seq: int | None = None
        self._last_t_us: float | None = None
        self._t_offset_us = 0.0
        self._synced = False  # a valid frame seen since the stream (re)started

    def _new_mav(self) -> None:
        self._mav = mavlink2.MAVLink(None)
        self._mav.robust_parsing = True

    def reset_stream(self) -> None:
        """Drop the partial frame (after a reconnect); sequence continuity is kept."""
        self._new_mav()
        self._synced = False

    def take_outgoing(self) -> list[bytes]:
        """Frames to send to the board (stream and identity requests), oldest first."""
        if self.link is None or not self.link.outgoing:
            return []
        out, self.link.outgoing = self.link.outgoing, []
        return out

    def board_meta(self) -> dict[str, str]:
        """What the board told about itself: firmware, uid, calibration parameters in use."""
        return self.link.meta() if self.link is not None else {}

    def take(self) -> SampleBlock | None:
        rows, self._rows = self._rows, []
        return SampleBlock.from_rows(rows)

    def feed(self, data: bytes) -> list:
        events: list = []
        if not data:
            return events
        st = self.stats
        st.bytes += len(data)
        msgs = self._mav.parse_buffer(bytes(data)) or []
        for m in msgs:
            t = m.get_type()
            if t == "BAD_DATA":
                if not self._synced:  # the tail of a frame sent before the port opened
                    continue
                reason = str(getattr(m, "reason", ""))
                kind = "noise" if "prefix" in reason else "checksum" if "CRC" in reason else "malformed"
                st.errors[kind] += 1
                continue
            st.sentences += 1
            self._synced = True
            key = (m.get_srcSystem(), m.get_srcComponent())
            if t == "HEARTBEAT":
                self.heartbeats[key] = self.heartbeats.get(key, 0) + 1
                self.autopilots[key] = int(m.autopilot)
            if self.link is not None:
                self.link.on_message(m, t, key, st.samples > 0)
            imu = t in IMU_MESSAGES and self._wanted(m, t, key, events)
            if key == self.system:
                seq = m.get_seq()
                frame = (seq, t, bytes(m.get_payload() or b""))
                repeat, self._last_frame = frame == self._last_frame, frame
                if self._last_seq is not None:
                    step = (seq - self._last_seq) % 256
                    if repeat:
                        st.duplicates += 1
                        continue
                    if step > 1:
                        st.gaps += step - 1
                        st.gap_events += 1
                self._last_seq = seq
            if imu:
                self._sample(m, t, events)
            else:
                st.unknown += 1
        return events

    def _wanted(self, m, t: str, key: tuple[int, int], events: list) -> bool:
        inst = _instance(m)
        if self.source is None:
            if self.want_type is not None and t != self.want_type:
                return False
            if self.want_id is not None and inst != self.want_id:
                return False
            self.source = f"{t}:{inst}"
            self.system = key
            self._units = IMU_MESSAGES[t]
            if t == "RAW_IMU" and self.autopilots.get(key, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA) not in (
                mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                mavlink2.MAV_AUTOPILOT_GENERIC,
            ):
                self._units = RAW_IMU_COUNTS
            acc, gyr, mag, *_ = self._units
            name = self.link.device_name(key) if self.link is not None else f"mavlink-{key[0]}-{key[1]}"
            self.header = Header(name, acc, gyr, mag, math.nan, 2, self.stats.samples)
            events.append(self.header)
            return True
        return self.source == f"{t}:{inst}" and self.system == key

    def _sample(self, m, t: str, events: list) -> None:
        st = self.stats
        _, _, _, k, kt, ktime = self._units
        if t.startswith("SCALED"):
            t_us = float(m.time_boot_ms) * ktime
        else:
            t_us = float(m.time_usec)
        temp = float(getattr(m, "temperature", 0) or 0)
        temp_c = math.nan if (temp == 0 and t != "HIGHRES_IMU") else temp * kt
        if self._last_t_us is not None and t_us < self._last_t_us:
            if t.startswith("SCALED") and self._last_t_us - t_us > _TIME_BOOT_MS_MODULO_US / 2:
                self._t_offset_us += _TIME_BOOT_MS_MODULO_US  # time_boot_ms wrapped (49.7 days)
            else:
                st.restarts += 1
                events.append(Restart(st.samples))
                self._t_offset_us = 0.0
        self._last_t_us = t_us
        self._rows.append(
            [
                m.get_seq(),
                t_us + self._t_offset_us,
                m.xacc * k,
                m.yacc * k,
                m.zacc * k,
                m.xgyro * k,
                m.ygyro * k,
                m.zgyro * k,
                m.xmag * k,
                m.ymag * k,
                m.zmag * k,
                temp_c,
            ]
        )
        st.samples += 1


class MavlinkEncoder:
    """MAVLink 2 HIGHRES_IMU (and optionally SCALED_IMU) frames for the simulated device.

    Values must already be in HIGHRES_IMU units (m/s^2, rad/s, gauss, degC).
    """

    def __init__(self, system: int = 1, component: int = 1, scaled_too: bool = False) -> None:
        self._mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
        self.scaled_too = scaled_too

    def _pack(self, msg) -> bytes:
        buf = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return bytes(buf)

    def skip(self, n: int = 1) -> None:
        """Advance the packet sequence as if n frames were sent (device-side drops)."""
        self._mav.seq = (self._mav.seq + n) % 256

    def heartbeat(self) -> bytes:
        return self._pack(
            self._mav.heartbeat_encode(
                mavlink2.MAV_TYPE_GENERIC, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, mavlink2.MAV_STATE_ACTIVE
            )
        )

    def imu(self, t_us: int, acc_mps2, gyro_rad_s, mag_gauss, temp_c: float) -> bytes:
        """One HIGHRES_IMU frame (plus SCALED_IMU when scaled_too); NaN fields sent as 0."""
        a = [0.0 if v != v else float(v) for v in acc_mps2]
        w = [0.0 if v != v else float(v) for v in gyro_rad_s]
        b = [0.0 if v != v else float(v) for v in mag_gauss]
        tc = 0.0 if temp_c != temp_c else float(temp_c)
        out = self._pack(self._mav.highres_imu_encode(int(t_us), *a, *w, *b, 0.0, 0.0, 0.0, tc, HIGHRES_FIELDS_ALL, 0))
        if self.scaled_too:
            g0 = 9.80665

            def i16(x: float) -> int:
                return max(-32768, min(32767, int(round(x))))

            tcs = i16(tc * 100) or 1  # 0 would mean "no sensor"
            out += self._pack(
                self._mav.scaled_imu_encode(
                    (int(t_us) // 1000) % (1 << 32),
                    *(i16(v / g0 * 1000) for v in a),
                    *(i16(v * 1000) for v in w),
                    *(i16(v * 1000) for v in b),
                    tcs,
                )
            )
        return out


def set_message_interval(msg_name: str, rate_hz: float, target_system: int = 1, target_component: int = 1) -> bytes:
    """A COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL asking a flight controller to stream msg_name."""
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    msg_id = getattr(mavlink2, f"MAVLINK_MSG_ID_{msg_name.upper()}")
    interval_us = 1e6 / rate_hz if rate_hz > 0 else -1
    return bytes(
        mav.command_long_encode(
            target_system,
            target_component,
            mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL,
            0,
            msg_id,
            interval_us,
            0,
            0,
            0,
            0,
            0,
        ).pack(mav)
    )


__all__ = ["IMU_MESSAGES", "MavlinkParser", "MavlinkEncoder", "set_message_interval", "ERROR_KINDS", "Unknown"]


# --- network endpoints and the board's identity (pymavlink's connection layer) ---------------

NETWORK_PREFIXES = ("udp:", "udpin:", "udpout:", "udpbcast:", "tcp:", "tcpin:")
PARAM_PREFIXES = ("INS_ACC", "INS_GYR", "COMPASS_", "AHRS_ORIENTATION", "CAL_ACC", "CAL_GYRO", "CAL_MAG", "SENS_BOARD_")
FIRMWARE = {mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot", mavlink2.MAV_AUTOPILOT_PX4: "px4"}


def compass_offsets_changed(first, now) -> set[str]:
    """The COMPASS_OFS_X/Y/Z whose value in SENSOR_OFFSETS' mag_ofs ``now`` (x, y, z) differs
    from the ``first`` seen: ArduPilot's learnt compass offsets, often sent with no PARAM_VALUE."""
    return {f"COMPASS_OFS_{a}" for a, v0, v in zip("XYZ", first, now) if v != v0}


def is_network(port: str) -> bool:
    """`udp:127.0.0.1:14550` (listen; MAVProxy's convention), `udpout:`, `tcp:host:5760`, `tcpin:`."""
    return port.lower().startswith(NETWORK_PREFIXES)


class NetworkPort:
    """A pymavlink network connection (mavutil.mavlink_connection) with the read/write/close
    interface the station's Reader uses for serial ports. `read` waits up to `timeout_s`."""

    def __init__(self, url: str, timeout_s: float = 0.02) -> None:
        from pymavlink import mavutil

        self.url, self.timeout_s = url, timeout_s
        # pymavlink prints its connect retries ("... sleeping") on stdout: the caller says why it failed
        with contextlib.redirect_stdout(io.StringIO()):
            self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190, autoreconnect=True)

    def read(self, n: int) -> bytes:
        import select

        sock = self.conn.port or getattr(self.conn, "listen", None)  # tcpin: the listening socket until accepted
        if sock is None:
            return b""
        ready, _, _ = select.select([sock], [], [], self.timeout_s)
        if not ready:
            return b""
        try:
            data = self.conn.recv(n)
        except BlockingIOError:
            return b""
        return bytes(data) if data else b""

    def write(self, data: bytes) -> int:
        self.conn.write(bytes(data))
        return len(data)

    def close(self) -> None:
        self.conn.close()


def _param_value(value: float, ptype: int, firmware: str | None) -> float | int:
    """PARAM_VALUE's float as the firmware stores the parameter: PX4 sends integer types
    byte-wise inside the float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), ArduPilot casts."""
    import struct

    ints = (
        mavlink2.MAV_PARAM_TYPE_INT32,
        mavlink2.MAV_PARAM_TYPE_UINT32,
        mavlink2.MAV_PARAM_TYPE_INT16,
        mavlink2.MAV_PARAM_TYPE_UINT16,
        mavlink2.MAV_PARAM_TYPE_INT8,
        mavlink2.MAV_PARAM_TYPE_UINT8,
    )
    if ptype in ints:
        if firmware == "px4":
            fmt = "<I" if ptype == mavlink2.MAV_PARAM_TYPE_UINT32 else "<i"
            return struct.unpack(fmt, struct.pack("<f", value))[0]
        return int(round(value))
    return float(value)


class BoardLink:
    """What the station asks a flight controller for, and what it learns about it.

    On each HEARTBEAT from an autopilot: MAV_CMD_REQUEST_MESSAGE for AUTOPILOT_VERSION until it
    answers; once the uid is known (or after two heartbeats without it), until IMU samples flow:
    REQUEST_DATA_STREAM
    (RAW_SENSORS, ArduPilot) and MAV_CMD_SET_MESSAGE_INTERVAL for the wanted message (PX4 and
    newer ArduPilot); and once
    PARAM_REQUEST_LIST (the calibration parameters in use). Frames to send are collected in
    `outgoing` (the Reader writes them)."""

    def __init__(self, want_type: str | None, rate_hz: float) -> None:
        self.want = want_type or "HIGHRES_IMU"
        self.rate_hz = rate_hz
        self.mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        self.outgoing: list[bytes] = []
        self.target: tuple[int, int] | None = None
        self.firmware: str | None = None
        self.uid: str | None = None
        self.params: dict[str, float | int] = {}
        self.changed: set[str] = set()  # calibration parameters whose value changed while streaming
        self.param_count: int | None = None
        self._asked_params = False
        self._heartbeats = 0
        self._param_indices: set[int] = set()
        self._first_offsets: tuple[int, int, int] | None = None  # SENSOR_OFFSETS' mag_ofs when first seen

    def _send(self, msg) -> None:
        self.outgoing.append(bytes(msg.pack(self.mav)))
        self.mav.seq = (self.mav.seq + 1) % 256

    def _request_stream(self, key: tuple[int, int]) -> None:
        s, c = key
        self._send(
            self.mav.request_data_stream_encode(s, c, mavlink2.MAV_DATA_STREAM_RAW_SENSORS, int(round(self.rate_hz)), 1)
        )
        msg_id = getattr(mavlink2, f"MAVLINK_MSG_ID_{self.want}")
        self._send(
            self.mav.command_long_encode(
                s, c, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / self.rate_hz, 0, 0, 0, 0, 0
            )
        )

    def on_message(self, m, t: str, key: tuple[int, int], streaming: bool) -> None:
        if t == "HEARTBEAT" and m.autopilot != mavlink2.MAV_AUTOPILOT_INVALID and m.type != mavlink2.MAV_TYPE_GCS:
            self.target = self.target or key
            self.firmware = self.firmware or FIRMWARE.get(int(m.autopilot))
            if key != self.target:
                return
            s, c = key
            self._heartbeats += 1
            # the uid first (it names the device in the capture header), the stream after it or
            # after two heartbeats without an answer
            if not streaming and (self.uid is not None or self._heartbeats > 2):
                self._request_stream(key)
            if self.uid is None:
                self._send(
                    self.mav.command_long_encode(
                        s,
                        c,
                        mavlink2.MAV_CMD_REQUEST_MESSAGE,
                        0,
                        mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                        0,
                        0,
                        0,
                        0,
                        0,
                        0,
                    )
                )
            if not self._asked_params:
                self._asked_params = True
                self._send(self.mav.param_request_list_encode(s, c))
        elif t == "AUTOPILOT_VERSION" and key == self.target:
            uid2 = bytes(getattr(m, "uid2", b"") or b"")
            first = self.uid is None
            if m.uid:
                self.uid = f"{int(m.uid):016x}"
            elif any(uid2):
                self.uid = uid2.hex()
            else:
                self.uid = ""  # the board has no uid: named by sysid/compid
            if first and not streaming:  # the name is known: ask for the stream now
                self._request_stream(key)
        elif t == "PARAM_VALUE" and key == self.target:
            name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode("ascii", "replace")
            name = name.rstrip("\x00")
            self.param_count = int(m.param_count)
            self._param_indices.add(int(m.param_index))
            if name.startswith(PARAM_PREFIXES):
                value = _param_value(float(m.param_value), int(m.param_type), self.firmware)
                # the first value is the one in use since the stream began; a later different one is
                # a change while the data run (a board sends PARAM_VALUE when it saves a parameter:
                # ArduPilot's in-flight compass learning, COMPASS_LEARN): said, never taken as in use
                if name in self.params and self.params[name] != value:
                    self.changed.add(name)
                else:
                    self.params.setdefault(name, value)

        elif t == "SENSOR_OFFSETS" and key == self.target:
            # ArduPilot's primary compass offsets in use (mGauss): learnt in flight, they change
            # here, often with no PARAM_VALUE sent (as the .tlog importer reads them)
            ofs = (int(m.mag_ofs_x), int(m.mag_ofs_y), int(m.mag_ofs_z))
            if self._first_offsets is None:
                self._first_offsets = ofs
            else:
                self.changed.update(compass_offsets_changed(self._first_offsets, ofs))

    def device_name(self, key: tuple[int, int]) -> str:
        if self.uid:
            return f"{self.firmware or 'mavlink'}-{self.uid}"
        return f"mavlink-{key[0]}-{key[1]}"

    def meta(self) -> dict[str, str]:
        out: dict[str, str] = {}
        if self.firmware:
            out["firmware"] = self.firmware
            out["corrected"] = "true"  # RAW_IMU/SCALED_IMU*/HIGHRES_IMU of both firmwares: calibrated, rotated
        if self.uid:
            out["autopilot_uid"] = self.uid
        if self.changed:  # as the log importers write it; the exports compose with none of these
            out["params_changed"] = ",".join(sorted(self.changed))
        if self.param_count is not None:  # PARAM_VALUEs received of the board's total (UDP may lose some)
            out["params_received"] = f"{len(self._param_indices)}/{self.param_count}"
        for name in sorted(self.params):
            v = self.params[name]  # floats as the shortest text of the float32 the board keeps
            out[f"param.{name}"] = (
                str(v) if isinstance(v, int) else np.format_float_positional(np.float32(v), unique=True, trim="-")
            )
        ids = {
            "INS_ACC_ID": "accel_device_id",
            "INS_GYR_ID": "gyro_device_id",
            "COMPASS_DEV_ID": "mag_device_id",
            "CAL_ACC0_ID": "accel_device_id",
            "CAL_GYRO0_ID": "gyro_device_id",
            "CAL_MAG0_ID": "mag_device_id",
        }
        for p, key in ids.items():
            if self.params.get(p):
                out[key] = str(int(self.params[p]))
        return out
