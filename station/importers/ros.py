"""ROS 1 bags (``.bag``), ROS 2 bags (a folder with ``metadata.yaml``, or its ``.db3`` / ``.mcap``
file) and plain MCAP files with ROS 2 messages, through the pure-Python ``rosbags`` reader.

Messages (ROS's ``sensor_msgs`` definitions): ``Imu.linear_acceleration`` m/s² and
``Imu.angular_velocity`` rad/s (a covariance whose first element is −1 means "not provided":
that part is left out); ``MagneticField.magnetic_field`` in tesla, written to the capture in nT;
``Temperature.temperature`` °C. Time is each message's ``header.stamp`` (the sensor's time),
or the bag's receive time where the stamp is zero.

Whether a driver calibrated its output is not recorded in a bag, so no ``corrected`` key.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from station.errors import InputError
from station.importers._common import Imported, Stream, set_date

IMU = "sensor_msgs/msg/Imu"
MAG = "sensor_msgs/msg/MagneticField"
TEMP = "sensor_msgs/msg/Temperature"
SUFFIXES = (".bag", ".db3", ".mcap")
ROS1_MAGIC = b"#ROSBAG V2.0\n"  # the first line of every ROS 1 bag (format 2.0, the one rosbag writes)


def is_bag(path) -> bool:
    p = Path(path)
    return p.suffix.lower() in SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def _one_frame(rows: list, more: list, topic, warnings: list[str]) -> tuple[list, list, str | None]:
    """``rows`` and ``more`` ((t, x, y, z, frame_id) of one topic) as (t, x, y, z) of the frame_id
    with the most samples (the first on a tie), and that frame_id when the topic carried several
    (said in ``warnings``), else None."""
    counts = Counter(r[-1] for r in (rows or more))  # messages per frame_id
    keep = None
    if len(counts) > 1:
        keep = max(counts, key=lambda f: (counts[f], -list(counts).index(f)))
        others = ", ".join(f"{f or '(empty)'} ({n})" for f, n in counts.items() if f != keep)
        warnings.append(
            f"{topic} carries {len(counts)} sensors (frame_id): read {keep or '(empty)'}'s {counts[keep]} samples; "
            f"{others} left out"
        )
    return (
        [r[:-1] for r in rows if keep is None or r[-1] == keep],
        [r[:-1] for r in more if keep is None or r[-1] == keep],
        keep,
    )


def _stamp(msg, fallback_ns: int) -> int:
    """The header stamp in integer ns (the bag's receive time where it is zero)."""
    st = msg.header.stamp
    ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
    return ns if ns else int(fallback_ns)


def _pick(path, found: dict[str, int], want: str | None, what: str) -> str | None:
    if want is not None:
        if want not in found:
            listed = ", ".join(sorted(found)) or "none"
            raise InputError(
                path,
                None,
                f"--topic {want}: no {what} topic of that name (the bag's {what} topics: {listed})",
            )
        return want
    if len(found) > 1:
        raise InputError(
            path,
            None,
            f"several {what} topics ({', '.join(sorted(found))}): choose one with "
            f"--topic {'imu' if what == 'Imu' else 'mag'}=NAME",
        )
    return next(iter(found), None)


def read(path, *, topics: dict[str, str] | None = None, kinds=None) -> Imported:
    """The Imu (accel + gyro), MagneticField and Temperature topics of a bag.

    ``topics``: ``{"imu": "/imu0", "mag": "/mag", "temp": "/imu/temp"}``, needed only where a bag
    has more than one topic of a type.
    """
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    topics = dict(topics or {})
    p = Path(path)
    if not p.exists():
        raise InputError(path, None, "no such file")
    if p.suffix.lower() == ".bag" and p.is_file():  # rosbags reads the whole file before it looks at the magic
        from station.fileio import open_input

        with open_input(path, "a ROS bag") as f:
            magic = f.read(len(ROS1_MAGIC))
        if magic != ROS1_MAGIC:
            raise InputError(path, None, "not a ROS 1 bag (it does not start with '#ROSBAG V2.0')")
    store = get_typestore(Stores.ROS1_NOETIC if p.suffix.lower() == ".bag" else Stores.LATEST)
    try:
        reader = AnyReader([p], default_typestore=store)
        reader.open()
    except (AnyReaderError, Exception) as exc:  # noqa: BLE001 - any reader failure is one line
        raise InputError(
            path,
            None,
            f"not a readable ROS bag or MCAP file ({type(exc).__name__}: {exc})",
        ) from None
    try:
        by_type: dict[str, dict[str, int]] = {IMU: {}, MAG: {}, TEMP: {}}
        for c in reader.connections:
            if c.msgtype in by_type:
                by_type[c.msgtype][c.topic] = by_type[c.msgtype].get(c.topic, 0) + c.msgcount
        imu_topic = _pick(path, by_type[IMU], topics.get("imu"), "Imu")
        mag_topic = _pick(path, by_type[MAG], topics.get("mag"), "MagneticField")
        temp_topic = _pick(path, by_type[TEMP], topics.get("temp"), "Temperature") if by_type[TEMP] else None
        if imu_topic is None and mag_topic is None:
            kinds_found = sorted({c.msgtype for c in reader.connections}) or ["no messages"]
            raise InputError(
                path,
                None,
                "no sensor_msgs/Imu or sensor_msgs/MagneticField topic "
                f"(the bag holds {', '.join(kinds_found[:6])}{' …' if len(kinds_found) > 6 else ''})",
            )
        chosen = {t for t in (imu_topic, mag_topic, temp_topic) if t}
        conns = [c for c in reader.connections if c.topic in chosen]
        acc, gyr, mag, temp = [], [], [], []
        frames: set[str] = set()
        first_ns = None
        for conn, t_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            first_ns = t_ns if first_ns is None else min(first_ns, t_ns)
            t = _stamp(msg, t_ns)
            if conn.topic == imu_topic:
                frame = msg.header.frame_id
                frames.add(frame)
                if msg.linear_acceleration_covariance[0] != -1:
                    a = msg.linear_acceleration
                    acc.append((t, a.x, a.y, a.z, frame))
                if msg.angular_velocity_covariance[0] != -1:
                    w = msg.angular_velocity
                    gyr.append((t, w.x, w.y, w.z, frame))
            elif conn.topic == mag_topic:
                f = msg.magnetic_field
                mag.append((t, f.x * 1e9, f.y * 1e9, f.z * 1e9, msg.header.frame_id))  # T → nT
            else:
                temp.append((t, msg.temperature))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, None, f"cannot read the bag ({type(exc).__name__}: {exc})") from None
    finally:
        reader.close()
    warnings: list[str] = []
    # one topic carrying several sensors (a relay, a mux), told apart by frame_id: one sensor's
    # samples, not theirs interleaved
    acc, gyr, imu_frame = _one_frame(acc, gyr, imu_topic, warnings)
    mag, _, _ = _one_frame(mag, [], mag_topic, warnings)
    if imu_frame is not None:
        frames = {imu_frame}
    # seconds from the earliest stamp, subtracted in integer ns (Unix ns in a float lose 0.2 µs)
    origin = min((r[0] for rows in (acc, gyr, mag, temp) for r in rows[:1]), default=0)
    acc, gyr, mag, temp = ([((r[0] - origin) * 1e-9, *r[1:]) for r in rows] for rows in (acc, gyr, mag, temp))
    streams: dict[str, Stream] = {}
    for kind, rows, unit, topic in (
        ("accel", acc, "m/s^2", imu_topic),
        ("gyro", gyr, "rad/s", imu_topic),
        ("mag", mag, "nT", mag_topic),
    ):
        if rows and (kinds is None or kind in kinds):
            arr = np.asarray(rows, dtype=np.float64)
            streams[kind] = Stream(kind, arr[:, 0], arr[:, 1:4], unit, f"{topic} ({kind})")
    if temp and "accel" in streams:
        tt = np.asarray(temp, dtype=np.float64)
        a = streams["accel"]
        a.temp_c = np.interp(a.t_s, tt[:, 0], tt[:, 1], left=np.nan, right=np.nan)
    meta: dict[str, str] = {}
    if first_ns and first_ns > 946684800 * 10**9:  # a bag's receive clock is UTC wall time
        set_date(meta, warnings, first_ns * 1e-9, "bag's receive")
    frames.discard("")
    if len(frames) == 1:
        meta["frame_id"] = frames.pop()
    return Imported(streams, meta, warnings)
