"""Node per-message cost: the compensator node's gyro callback timed on its own, learning off/on.

A real :class:`fog_temp_comp.ros.node.CompensatorNode` (``config/example_coefficients.yaml``,
``kalman``) gets 30 min of 1 Hz temperature through its temperature callback (warm: the Tdot
terms and, with ``rest_learning``, the bias learner run), then ``--messages`` real
``sensor_msgs/Imu`` of a still unit at 100 Hz through ``_on_imu`` (a 1 Hz Temperature
interleaved, its time included, as ``bench_core.py``'s loop): message to floats, the core's
``correct_xyz`` (with the accelerometer when learning), the corrected rate back into the
message, ``publish`` (no subscriber: rclpy still serializes). No DDS transport, no executor: that
the relay's cost too (``bench_node.py``). ``relay`` is that floor: the same loop publishing the
message unchanged (and nothing for the temperature); ``own`` = callback minus relay, what the
compensator adds. A fourth variant sets ``sensor_lag_s`` (the Kalman filter on the coil behind
the sensor's lag, :mod:`fog_temp_comp.core.tdot_kalman_lag`); the example file's filter uses
the quantized likelihood (:mod:`fog_temp_comp.core.tdot_kalman_quantized`), and a fifth
variant turns it off (Gaussian readings). Rounds run every variant; best round per variant.
Goal: <= 20 us per message of own cost.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import rclpy
from benchutil import machine
from rclpy.context import Context
from rclpy.parameter import Parameter
from sensor_msgs.msg import Imu, Temperature

from fog_temp_comp.ros.node import CompensatorNode

COEFFICIENTS = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
START_S = 1_700_000_000


def per_message_us(
    context: Context, learning: bool | None, n: int, overrides: dict[str, float]
) -> float:
    """Mean microseconds per ``_on_imu`` call over ``n`` messages after a warm-up.

    ``overrides``: node parameters (name -> value) beside the coefficients file.
    """
    params = [Parameter('coefficients_file', value=str(COEFFICIENTS))]
    if learning:
        params += [Parameter('rest_learning', value=True)]
    params += [Parameter(name, value=value) for name, value in overrides.items()]
    node = CompensatorNode(context=context, parameter_overrides=params)
    try:
        temp = Temperature()
        for k in range(1800):
            temp.header.stamp.sec = START_S + k
            temp.temperature = 20.0 + k / 600.0
            node._on_temperature(temp)
        assert node.compensator.status.estimator_ready
        msgs: list[tuple[bool, Imu | Temperature]] = []
        for i in range(n):
            ns = (START_S + 1800) * 10**9 + i * 10_000_000
            if i % 100 == 0:  # 1 Hz temperature interleaved, as a replay
                t = Temperature()
                t.header.stamp.sec, t.header.stamp.nanosec = divmod(ns, 10**9)
                t.temperature = 23.0 + i / 60000.0
                msgs.append((False, t))
            msg = Imu()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 10**9)
            msg.angular_velocity.x, msg.linear_acceleration.z = -6e-5, 9.81
            msgs.append((True, msg))
        on_imu, on_temperature = node._on_imu, node._on_temperature
        if learning is None:  # the relay: publish what came in
            on_imu, on_temperature = node._publisher.publish, _ignore
        t0 = time.perf_counter()
        for is_imu, m in msgs:
            if is_imu:
                on_imu(m)  # type: ignore[arg-type]
            else:
                on_temperature(m)  # type: ignore[arg-type]
        elapsed = time.perf_counter() - t0
        if learning is None:
            return elapsed / n * 1e6
        assert node.compensator.status.counters.imu_corrected == n
        if learning:
            assert node.compensator.rest is not None
            assert node.compensator.rest.status.windows_rest > 0  # it really learned
        return elapsed / n * 1e6
    finally:
        node.destroy_node()


def _ignore(msg: object) -> None:
    pass


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--messages', type=int, default=30000)
    parser.add_argument('--rounds', type=int, default=3)
    args = parser.parse_args()
    context = Context()
    rclpy.init(context=context)
    variants: dict[str, tuple[bool | None, dict[str, float]]] = {
        'relay': (None, {}),
        'off': (False, {}),
        'on': (True, {}),
        'sensor_lag': (False, {'sensor_lag_s': 300.0}),
        'gaussian': (False, {'kalman_quantized_noise_degC': 0.0}),
    }
    best = dict.fromkeys(variants, float('inf'))
    try:
        for _ in range(args.rounds):
            for name, (learning, extra) in variants.items():
                us = per_message_us(context, learning, args.messages, extra)
                best[name] = min(best[name], us)
    finally:
        rclpy.try_shutdown(context=context)
    print(f'# bench_callback: {args.rounds} rounds x {args.messages} Imu; {machine()}')
    relay = best['relay']
    print('| variant | callback us/msg (best round) | own us/msg (minus relay) |')
    print('|---|---|---|')
    print(f'| relay (publish only) | {relay:.2f} | - |')
    labels = {
        'off': 'compensator, rest learning off',
        'on': 'compensator, rest learning on',
        'sensor_lag': 'compensator, sensor-lag Kalman (sensor_lag_s 300), learning off',
        'gaussian': 'compensator, Gaussian readings (kalman_quantized_noise_degC 0), learning off',
    }
    for key, label in labels.items():
        print(f'| {label} | {best[key]:.2f} | {best[key] - relay:.2f} |')
    worst = max(best[key] for key in labels) - relay
    print(f'goal <= 20 us/msg own cost: {"met" if worst <= 20 else "NOT met"} ({worst:.2f} us)')


if __name__ == '__main__':
    main()
