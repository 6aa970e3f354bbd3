"""A genuine ROS 1 bag (Header with seq, written with ROS 1 Noetic types) end to end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.coefficients import load, save
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import SimulatedRun


def write_noetic_bag(path: Path, run: SimulatedRun) -> None:
    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    header = types['std_msgs/msg/Header']
    time = types['builtin_interfaces/msg/Time']
    vec = types['geometry_msgs/msg/Vector3']
    quat = types['geometry_msgs/msg/Quaternion']
    events = sorted(
        [(t, 0, k) for k, t in enumerate(run.temp_stamps_s)]
        + [(t, 1, k) for k, t in enumerate(run.imu_stamps_s)]
    )
    with Writer(path) as writer:
        temp = writer.add_connection('/imu/temperature', 'sensor_msgs/msg/Temperature',
                                     typestore=store)  # fmt: skip
        imu = writer.add_connection('/imu/data_raw', 'sensor_msgs/msg/Imu', typestore=store)
        for seq, (t, kind, k) in enumerate(events):
            ns = round(t * 1e9)
            h = header(seq=seq, stamp=time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id='imu')
            if kind == 0:
                msg = types['sensor_msgs/msg/Temperature'](
                    header=h, temperature=float(run.temperature_degC[k]), variance=0.0
                )
                writer.write(temp, ns, store.serialize_ros1(msg, temp.msgtype))
            else:
                w = run.rates_rad_s[k]
                msg = types['sensor_msgs/msg/Imu'](
                    header=h,
                    orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=np.array([-1.0] + [0.0] * 8),
                    angular_velocity=vec(x=float(w[0]), y=float(w[1]), z=float(w[2])),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vec(x=0.0, y=0.0, z=9.81),
                    linear_acceleration_covariance=np.zeros(9),
                )
                writer.write(imu, ns, store.serialize_ros1(msg, imu.msgtype))


def test_noetic_bag_reads_and_compensates(
    tmp_path: Path, short_cycle_fast: SimulatedRun, capsys: object
) -> None:
    bag = tmp_path / 'noetic.bag'
    write_noetic_bag(bag, short_cycle_fast)
    record = read_record(bag)
    assert_array_equal(record.rates_rad_s, short_cycle_fast.rates_rad_s)
    assert_array_equal(record.temperature_degC, short_cycle_fast.temperature_degC)
    coeffs_path = tmp_path / 'c.yaml'
    save(calibrate([record], DenoiseSettings(method='iir')), coeffs_path)
    out = tmp_path / 'out.bag'
    assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs_path), '-o', str(out)]) == 0
    # the output reads back with rosbags, keeps seq, and holds the core's numbers
    with AnyReader([out]) as reader:
        conns = [c for c in reader.connections if c.topic == '/imu/data']
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    corrected = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                          for m in msgs])  # fmt: skip
    expected = compensate_record(record, load(coeffs_path))
    assert_allclose(corrected, expected, rtol=0, atol=1e-18)
    assert all(m.header.seq > 0 for m in msgs[1:])
    assert all(m.linear_acceleration.z == 9.81 for m in msgs)
