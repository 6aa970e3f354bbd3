"""Soak: drive the compensator node in-process with hours of fast-forwarded 1 kHz data.

Publishes gyro (``--rate-hz``) and 1 Hz temperature in chunks over reliable QoS (so nothing is
dropped by the middleware), spins until the node has published every corrected message, and
samples the process RSS. Reports messages lost (must be 0) and RSS growth after warm-up.

    .venv/bin/python benchmarks/soak.py --minutes 60 --rate-hz 1000
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, Temperature

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from rosharness import make_imu, make_temperature  # noqa: E402

from fog_temp_comp.ros.node import CompensatorNode  # noqa: E402

CHUNK = 1000  # below Fast DDS's default history limit of 5000 samples


@dataclass(frozen=True)
class SoakResult:
    """What a soak run measured."""

    imu_sent: int
    imu_received: int
    wall_s: float
    rss_mib: list[float]  # sampled once per simulated minute

    @property
    def lost(self) -> int:
        """Corrected messages that never arrived."""
        return self.imu_sent - self.imu_received

    @property
    def rss_growth_mib(self) -> float:
        """RSS growth from the end of the first simulated quarter to the end."""
        start = self.rss_mib[len(self.rss_mib) // 4]
        return self.rss_mib[-1] - start


def rss_mib() -> float:
    """Current resident set size of this process (MiB), from /proc."""
    for line in Path('/proc/self/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def soak(
    seconds: float, rate_hz: float, coefficients_file: Path, *, denoise: str = 'wavelet'
) -> SoakResult:
    """Run ``seconds`` of simulated time at ``rate_hz`` through a node; see module docstring."""
    context = Context()
    rclpy.init(context=context)
    qos = QoSProfile(depth=CHUNK, reliability=ReliabilityPolicy.RELIABLE)
    params = [
        Parameter('coefficients_file', value=str(coefficients_file)),
        Parameter('denoise', value=denoise),
    ]
    for topic, kind in (('/imu/data_raw', 'subscription'), ('/imu/data', 'publisher')):
        params += [
            Parameter(f'qos_overrides.{topic}.{kind}.reliability', value='reliable'),
            Parameter(f'qos_overrides.{topic}.{kind}.depth', value=CHUNK),
        ]
    for topic in ('/imu/temperature',):
        params += [
            Parameter(f'qos_overrides.{topic}.subscription.reliability', value='reliable'),
            Parameter(f'qos_overrides.{topic}.subscription.depth', value=CHUNK),
        ]
    node = CompensatorNode(context=context, parameter_overrides=params)
    peer = Node('soak_peer', context=context)
    imu_pub = peer.create_publisher(Imu, 'imu/data_raw', qos)
    temp_pub = peer.create_publisher(Temperature, 'imu/temperature', qos)
    received = 0

    def count(_msg: Imu) -> None:
        nonlocal received
        received += 1

    peer.create_subscription(Imu, 'imu/data', count, qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(peer)
    for _ in range(1000):  # discovery
        if imu_pub.get_subscription_count() and peer.count_publishers('/imu/data'):
            break
        executor.spin_once(timeout_sec=0.01)
    t0 = 1.7e9
    n_imu = round(seconds * rate_hz)
    rng = np.random.default_rng(0)
    rss: list[float] = []
    sent = 0
    next_temp_s = 0.0
    per_minute = round(60 * rate_hz)
    start = time.perf_counter()
    try:
        while sent < n_imu:
            batch = min(CHUNK, n_imu - sent)
            noise = rng.normal(0, 1e-6, (batch, 3))
            for k in range(sent, sent + batch):
                t = k / rate_hz
                if t >= next_temp_s:
                    temp = 20.0 + 10.0 * np.sin(2 * np.pi * t / 3600.0)
                    temp_pub.publish(make_temperature(t0 + t, round(temp * 16) / 16))
                    next_temp_s += 1.0
                imu_pub.publish(make_imu(t0 + t, noise[k - sent]))
            sent += batch
            for _ in range(100_000):
                if received >= sent:
                    break
                executor.spin_once(timeout_sec=0.01)
            else:
                break
            if sent % per_minute < CHUNK:
                rss.append(rss_mib())
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()
        rclpy.shutdown(context=context)
    if not rss:
        rss.append(rss_mib())
    return SoakResult(sent, received, time.perf_counter() - start, rss)


def main() -> int:
    """Command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--minutes', type=float, default=60.0, help='simulated minutes')
    parser.add_argument('--rate-hz', type=float, default=1000.0, help='gyro rate (Hz)')
    parser.add_argument('--denoise', default='wavelet')
    parser.add_argument(
        '--coeffs', type=Path, default=ROOT / 'config' / 'example_coefficients.yaml'
    )
    args = parser.parse_args()
    result = soak(args.minutes * 60.0, args.rate_hz, args.coeffs, denoise=args.denoise)
    print(
        f'gyro messages sent {result.imu_sent}, corrected received {result.imu_received}, '
        f'lost {result.lost}'
    )
    print(
        f'wall time {result.wall_s:.1f} s ({result.imu_sent / result.wall_s:.0f} msg/s, '
        f'{args.minutes * 60 / result.wall_s:.1f}x real time)'
    )
    print(f'RSS per simulated minute (MiB): {[round(x, 1) for x in result.rss_mib]}')
    print(f'RSS growth after the first quarter: {result.rss_growth_mib:+.1f} MiB')
    return 0 if result.lost == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
