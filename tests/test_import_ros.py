"""`station import` of ROS 1 bags, ROS 2 bags (sqlite3 and MCAP storage) and MCAP files.

No real bag is in ../shared, so the bags here are WRITTEN BY ROSBAGS' OWN WRITERS
(``rosbags.rosbag1.Writer``, ``rosbags.rosbag2.Writer`` with its sqlite3 and MCAP storage
plugins), with messages serialized by rosbags from ROS's own ``sensor_msgs`` definitions
(Imu: m/s², rad/s; MagneticField: tesla; Temperature: °C).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from station.capture import read_capture
from tests.station_run import run_station

T0_NS = 1_700_000_000_000_000_000  # 2023-11-14T22:13:20Z


def _messages(
    ts,
    rng,
    n_imu=400,
    imu_hz=200.0,
    mag_hz=50.0,
    mag_only=False,
    hard_iron_nT=(0.0, 0.0, 0.0),
):
    """(topic, msgtype, stamp_ns, message) in time order, and what was put in."""
    T = ts.types
    Time, Header, Vec3, Quat = (
        T["builtin_interfaces/msg/Time"],
        T["std_msgs/msg/Header"],
        T["geometry_msgs/msg/Vector3"],
        T["geometry_msgs/msg/Quaternion"],
    )
    cov = np.zeros(9)
    out, truth = [], {"acc": [], "gyr": [], "mag": [], "t_imu": [], "t_mag": []}

    def header(ns):
        stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
        if "seq" in Header.__dataclass_fields__:  # ROS 1's Header has a sequence number
            return Header(seq=0, stamp=stamp, frame_id="imu_link")
        return Header(stamp=stamp, frame_id="imu_link")

    if not mag_only:
        for k in range(n_imu):
            ns = T0_NS + round(k * 1e9 / imu_hz)
            a = np.array([0.05, -0.1, 9.81]) + rng.normal(0, 0.02, 3)
            w = rng.normal(0, 0.001, 3)
            msg = T["sensor_msgs/msg/Imu"](
                header=header(ns),
                orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=cov,
                angular_velocity=Vec3(x=w[0], y=w[1], z=w[2]),
                angular_velocity_covariance=cov,
                linear_acceleration=Vec3(x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=cov,
            )
            out.append(("/imu/data", "sensor_msgs/msg/Imu", ns, msg))
            truth["acc"].append(a), truth["gyr"].append(w), truth["t_imu"].append(ns)
    n_mag = int(n_imu * mag_hz / imu_hz)
    dirs = rng.normal(size=(n_mag, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for k in range(n_mag):
        ns = T0_NS + 1_000_000 + round(k * 1e9 / mag_hz)
        b_T = (48_000.0 * dirs[k] + np.asarray(hard_iron_nT)) * 1e-9 + rng.normal(0, 20e-9, 3)
        msg = T["sensor_msgs/msg/MagneticField"](
            header=header(ns),
            magnetic_field=Vec3(x=b_T[0], y=b_T[1], z=b_T[2]),
            magnetic_field_covariance=cov,
        )
        out.append(("/mag", "sensor_msgs/msg/MagneticField", ns, msg))
        truth["mag"].append(b_T), truth["t_mag"].append(ns)
    out.sort(key=lambda m: m[2])
    return out, {k: np.asarray(v) for k, v in truth.items()}


def write_ros1(path, msgs):
    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as w:
        conns = {}
        for topic, typ, ns, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
            w.write(conns[topic], ns, ts.serialize_ros1(msg, typ))


def write_ros2(path, msgs, storage):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(path, version=9, storage_plugin=storage) as w:
        conns = {}
        for topic, typ, ns, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
            w.write(conns[topic], ns, ts.serialize_cdr(msg, typ))


def _bag(kind, tmp_path, msgs):
    if kind == "ros1":
        path = tmp_path / "run.bag"
        write_ros1(path, msgs)
        return path
    folder = tmp_path / f"run_{kind}"
    write_ros2(
        folder,
        msgs,
        StoragePlugin.SQLITE3 if kind == "ros2-sqlite3" else StoragePlugin.MCAP,
    )
    if kind == "mcap-file":  # the .mcap file alone, as robotics tools pass it around
        return next(folder.glob("*.mcap"))
    return folder


@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "ros2-mcap", "mcap-file"])
def test_bag_round_trip(tmp_path, kind):
    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    msgs, truth = _messages(ts, np.random.default_rng(1))
    bag = _bag(kind, tmp_path, msgs)
    out = tmp_path / "bag.csv"
    res = run_station("import", bag, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    m = c.meta
    assert (m["accel_unit"], m["gyro_unit"], m["mag_unit"]) == ("m/s^2", "rad/s", "nT")
    assert "corrected" not in m and "firmware" not in m  # a bag does not say
    assert m["frame_id"] == "imu_link" and m["date"] == "2023-11-14T22:13:20"
    # rows: the Imu samples from the first compass sample on, values exact, t from header.stamp
    t_imu = truth["t_imu"]
    first = int(np.flatnonzero(t_imu >= truth["t_mag"][0])[0])
    n = c.n_rows
    np.testing.assert_array_equal(c.columns["gx"], truth["gyr"][first : first + n, 0])
    np.testing.assert_array_equal(c.columns["az"], truth["acc"][first : first + n, 2])
    np.testing.assert_allclose(c.columns["t"], (t_imu[first : first + n] - t_imu[first]) * 1e-9, atol=1e-9)
    assert abs(float(m["sample_rate_hz"]) - 200) < 1e-6
    # the 50 Hz compass, tesla → nT, interpolated onto the rows: |B| near 48 µT
    b = np.linalg.norm(np.column_stack([c.columns["mx"], c.columns["my"], c.columns["mz"]]), axis=1)
    assert 30_000 < np.nanmedian(b) < 49_000


def test_several_imu_topics_need_a_choice(tmp_path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    msgs, _ = _messages(ts, np.random.default_rng(2))
    msgs2 = [("/imu/raw" if t == "/imu/data" else t, typ, ns, msg) for t, typ, ns, msg in msgs]
    both = sorted(msgs + [m for m in msgs2 if m[0] == "/imu/raw"], key=lambda m: m[2])
    bag = tmp_path / "two_imus"
    write_ros2(bag, both, StoragePlugin.SQLITE3)
    res = run_station("import", bag, "--procedure", "gyro-drift", "--out", tmp_path / "x.csv")
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert "/imu/data, /imu/raw" in res.stderr and "--topic imu=" in res.stderr
    assert not (tmp_path / "x.csv").exists()
    res = run_station(
        "import",
        bag,
        "--procedure",
        "gyro-drift",
        "--topic",
        "imu=/imu/raw",
        "--out",
        tmp_path / "x.csv",
    )
    assert res.returncode == 0, res.stderr
    assert "/imu/raw" in read_capture(tmp_path / "x.csv").meta["import_source"]


def test_magnetometer_only_bag_calibrates_as_compass_directly(tmp_path):
    """Only MagneticField in the bag: calibrate infers the compass procedure; the hard-iron
    offset put in (nT) comes back."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    hard = (1500.0, -800.0, 300.0)
    msgs, _ = _messages(ts, np.random.default_rng(4), n_imu=2400, mag_only=True, hard_iron_nT=hard)
    bag = tmp_path / "mag_only"
    write_ros2(bag, msgs, StoragePlugin.MCAP)
    res = run_station("calibrate", bag, "--json")
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert r["procedure"] == "compass"
    offset = np.asarray(r["params"]["hard_iron"], dtype=float)
    np.testing.assert_allclose(offset, hard, atol=60.0)  # 20 nT noise per axis, 600 samples


@pytest.mark.parametrize(
    "name, content, says",
    [
        ("broken.bag", b"#ROSBAG V2.0\n" + b"\x00" * 40, "not a readable ROS bag"),
        ("broken.mcap", b"this is not an mcap file", "not a readable ROS bag"),
    ],
)
def test_bad_bags_one_line(tmp_path, name, content, says):
    bad = tmp_path / name
    bad.write_bytes(content)
    res = run_station("import", bad, "--procedure", "gyro-drift", "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and res.stdout == "" and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and str(bad) in res.stderr and says in res.stderr, res.stderr
    assert not (tmp_path / "o.csv").exists()


def test_bag_without_sensor_topics_says_what_it_holds(tmp_path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    bag = tmp_path / "strings"
    msg = T["std_msgs/msg/String"](data="hello")
    write_ros2(bag, [("/chatter", "std_msgs/msg/String", T0_NS, msg)], StoragePlugin.SQLITE3)
    res = run_station("import", bag, "--procedure", "compass", "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and "std_msgs/msg/String" in res.stderr and "sensor_msgs/Imu" in res.stderr
