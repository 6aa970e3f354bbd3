"""Node throughput and latency: the compensator node against a do-nothing relay, in one process.

Both nodes under test (DUT) subscribe ``imu/data_raw`` and publish ``imu/data``
(``sensor_msgs/Imu``; the input best effort, keeping the last 100 (``node.IMU_INPUT_QOS``), the
output reliable, keeping the last 100 (``node.OUTPUT_QOS``); the sink best effort). The compensator
is :class:`fog_temp_comp.ros.node.CompensatorNode` with ``config/example_coefficients.yaml``; the
relay republishes the message it received. Per case a fresh rclpy context holds three nodes:

- ``source`` publishes Imu (header stamp = wall clock at publish, ``time.time_ns``, a new stamp
  per message) and a Temperature at 1 Hz of wall time (so the compensator really corrects);
- the DUT;
- ``sink`` subscribes ``imu/data`` and records receive time minus header stamp (latency).

DUT and sink spin in one ``SingleThreadedExecutor`` on the main thread. Modes:

- paced (200 Hz, 1 kHz, 2 kHz): a separate thread publishes on an absolute schedule
  (``time.sleep`` to each deadline, no catch-up bursts beyond the missed ones);
- ``max``: closed loop, all in the executor thread: 4 messages in flight (below the QoS depth
  of 5, so nothing can be dropped), the sink publishes the next message each time one arrives.
  The rate is the most the DUT + sink + publish can sustain: the max throughput.

The pacing thread shares the GIL with the executor: when the executor thread is busy, the
thread may wake late and publish the missed messages in a burst (Python's default 5 ms switch
interval), which a keep-last-5 queue can turn into drops even below the max throughput.
``--executor events`` runs the same cases on ``rclpy.experimental.EventsExecutor`` (C++).
``--rest-learning`` turns the compensator's bias learning at rest on (``rest_learning:=true``,
the accelerometer of each message fed to it too).

``--dut-process`` runs the DUT in a process of its own, as on a robot (driver and compensator
are separate processes): the compensator is ``fog_temp_comp.ros.node.main``, what ``ros2 run
fog_temp_comp compensator`` starts, with ``-p executor:=<--executor>``; the relay spins the
same way. Source and sink stay in this process (sink in a ``SingleThreadedExecutor``). The
compensator's correction is checked on the received rates instead of its counters.

``dropped`` = published - received after a 0.5 s drain. ``added latency`` = compensator minus
relay, at the same percentile. ``--rounds`` rounds run every case once (relay and compensator
alternating first), so that load from other processes hits both alike; ``max`` reports the
best round, the paced modes sum the drops and pool the latencies of all rounds. All nodes
live in a private namespace (``/bench_<pid>``) so other ROS processes on the machine do not
interfere. Goal: compensator >= 0.8x the relay's max throughput, and no drops at 2 kHz.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from benchutil import machine, table
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu, Temperature

from fog_temp_comp.ros.node import IMU_INPUT_QOS, OUTPUT_QOS, CompensatorNode

ROOT = Path(__file__).resolve().parents[1]
COEFFICIENTS = ROOT / 'config' / 'example_coefficients.yaml'
WINDOW = 4
SINK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10_000, reliability=ReliabilityPolicy.BEST_EFFORT
)
NS = f'/bench_{os.getpid()}'


class Relay(Node):
    """Do-nothing relay: same topics and QoS as the compensator, republishes what it gets."""

    def __init__(self, context: Context, namespace: str = NS) -> None:
        super().__init__('relay', namespace=namespace, context=context)
        self._publisher = self.create_publisher(Imu, 'imu/data', OUTPUT_QOS)
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, IMU_INPUT_QOS)

    def _on_imu(self, msg: Imu) -> None:
        self._publisher.publish(msg)


@dataclass
class Stats:
    """What the source sent and the sink got."""

    sent: int = 0
    latency_ns: list[int] = field(default_factory=list)
    last_rate_x: float = 0.0  # angular_velocity.x of the newest received message (rad/s)
    first_ns: int = 0
    last_ns: int = 0


class Source(Node):
    """Publishes Imu stamped with the wall clock, and a Temperature each wall-clock second."""

    def __init__(self, context: Context, namespace: str = NS) -> None:
        super().__init__('source', namespace=namespace, context=context)
        self.imu_pub = self.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
        self.temp_pub = self.create_publisher(
            Temperature, 'imu/temperature', qos_profile_sensor_data
        )
        self.imu = Imu()
        self.imu.header.frame_id = 'imu_link'
        self.imu.orientation.w = 1.0
        self.imu.orientation_covariance[0] = -1.0
        self.imu.angular_velocity.x = 1e-4
        self.temp = Temperature()
        self.temp.header.frame_id = 'imu_link'
        self.next_temp_ns = 0
        self.temperature_degC = 20.0

    def publish_imu(self) -> None:
        """One Imu (and a Temperature first when a second has passed)."""
        now = time.time_ns()
        if now >= self.next_temp_ns:
            self.next_temp_ns = now + 1_000_000_000
            self.temp.header.stamp.sec, self.temp.header.stamp.nanosec = divmod(
                now - 1000, 1_000_000_000
            )
            self.temperature_degC += 0.01
            self.temp.temperature = self.temperature_degC
            self.temp_pub.publish(self.temp)
        stamp = self.imu.header.stamp
        stamp.sec, stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        self.imu_pub.publish(self.imu)


class Sink(Node):
    """Records the latency of every ``imu/data`` message."""

    def __init__(self, context: Context, stats: Stats) -> None:
        # a harness node: no parameter services, to keep the executor's wait set small
        super().__init__('sink', namespace=NS, context=context, start_parameter_services=False)
        self.stats = stats
        self.on_receive: Callable[[], None] | None = None
        # best effort like the DUT's publisher, but a deep queue: the harness must not drop
        self.create_subscription(Imu, 'imu/data', self._on_imu, SINK_QOS)

    def _on_imu(self, msg: Imu) -> None:
        now = time.time_ns()
        stamp = msg.header.stamp
        stats = self.stats
        stats.latency_ns.append(now - (stamp.sec * 1_000_000_000 + stamp.nanosec))
        stats.last_rate_x = msg.angular_velocity.x
        stats.last_ns = now
        if not stats.first_ns:
            stats.first_ns = now
        if self.on_receive is not None:
            self.on_receive()


#: extra compensator parameters (``--rest-learning``), name -> value
EXTRA_PARAMETERS: dict[str, Any] = {}


def serve(kind: str, executor_name: str, namespace: str) -> None:
    """Child process of ``--dut-process``: spin the relay, or run the compensator's main()."""
    if kind == 'compensator':
        from fog_temp_comp.ros.node import main as compensator_main

        raise SystemExit(
            compensator_main(
                [
                    '--ros-args',
                    '-r',
                    f'__ns:={namespace}',
                    '-p',
                    f'coefficients_file:={COEFFICIENTS}',
                    '-p',
                    f'executor:={executor_name}',
                    *[
                        a
                        for n, v in EXTRA_PARAMETERS.items()
                        for a in ('-p', f'{n}:={v!s}'.lower())
                    ],
                ]
            )
        )
    context = Context()
    rclpy.init(context=context)
    relay = Relay(context, namespace)
    executor = make_executor(executor_name, context)
    executor.add_node(relay)
    try:
        while context.ok():
            executor.spin_once(timeout_sec=0.5)
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        relay.destroy_node()
        rclpy.try_shutdown(context=context)


class DutProcess:
    """The DUT in a child process (this script with ``--serve``); SIGINT and wait on close."""

    def __init__(self, kind: str, executor_name: str) -> None:
        command = [sys.executable, __file__, '--serve', kind, '--executor', executor_name]
        if EXTRA_PARAMETERS.get('rest_learning'):
            command.append('--rest-learning')
        self.proc = subprocess.Popen(
            [*command, '--namespace', NS], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )

    def check_alive(self) -> None:
        """Raise with the child's stderr if it has exited."""
        if self.proc.poll() is not None:
            _, err = self.proc.communicate()
            raise RuntimeError(f'DUT process exited with {self.proc.returncode}: {err.decode()}')

    def close(self) -> None:
        """Stop the child as Ctrl-C would (kill it if that takes over 10 s)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def make_dut(kind: str, context: Context) -> Node:
    if kind == 'relay':
        return Relay(context)
    return CompensatorNode(
        namespace=NS,
        context=context,
        parameter_overrides=[
            Parameter('coefficients_file', value=str(COEFFICIENTS)),
            *[Parameter(n, value=v) for n, v in EXTRA_PARAMETERS.items()],
        ],
    )


def spin_until(executor: Executor, done: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise RuntimeError('benchmark setup: condition not reached (discovery?)')
        executor.spin_once(timeout_sec=0.01)


def make_executor(name: str, context: Context) -> Executor:
    if name == 'events':
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def run_case(
    kind: str,
    mode: str,
    duration_s: float,
    executor_name: str = 'single',
    dut_process: bool = False,
) -> dict[str, Any]:
    """One DUT in one mode: rate (msg/s), sent, dropped, latencies (ms) and percentiles."""
    context = Context()
    rclpy.init(context=context)
    stats = Stats()
    # with the DUT in its own process, this process spins only the sink: single-threaded
    executor = make_executor('single' if dut_process else executor_name, context)
    source = Source(context)
    dut: Node | DutProcess = (
        DutProcess(kind, executor_name) if dut_process else make_dut(kind, context)
    )
    sink = Sink(context, stats)
    try:
        if isinstance(dut, Node):
            executor.add_node(dut)
        executor.add_node(sink)

        def discovered() -> bool:
            if isinstance(dut, DutProcess):
                dut.check_alive()
            return (
                source.imu_pub.get_subscription_count() > 0
                and (kind == 'relay' or source.temp_pub.get_subscription_count() > 0)
                and sink.count_publishers(f'{NS}/imu/data') > 0
            )

        spin_until(executor, discovered, 20.0)
        # warm-up: the data path works end to end and the compensator has a temperature
        source.next_temp_ns = 0
        spin_until(executor, lambda: bool(source.publish_imu()) or len(stats.latency_ns) > 0, 10.0)
        for _ in range(20):
            source.publish_imu()
            executor.spin_once(timeout_sec=0.01)
        drain(executor, 0.2)
        stats.latency_ns.clear()
        stats.first_ns = stats.last_ns = 0
        if mode == 'max':
            run_closed_loop(executor, source, sink, stats, duration_s)
        elif dut_process:
            run_paced_process(executor, stats, mode, duration_s, kind)
        else:
            run_open_loop(executor, source, stats, mode, duration_s)
        if isinstance(dut, CompensatorNode):  # it really corrected (had temperature)
            counters = dut.compensator.status.counters
            assert counters.imu_corrected > 0.9 * counters.imu_total, counters
        elif kind == 'compensator':  # the source sends zero rates: corrected = -drift
            assert stats.last_rate_x != source.imu.angular_velocity.x, 'not corrected'
    finally:
        executor.shutdown()
        for node in (sink, dut, source):
            if isinstance(node, DutProcess):
                node.close()
            else:
                node.destroy_node()
        rclpy.shutdown(context=context)
    received = len(stats.latency_ns)
    span_s = (stats.last_ns - stats.first_ns) / 1e9
    latency_ms = np.asarray(stats.latency_ns) / 1e6
    p50, p99 = np.percentile(latency_ms, [50, 99]) if received else (np.nan, np.nan)
    return {
        'rate': (received - 1) / span_s if span_s > 0 else float('nan'),
        'sent': stats.sent,
        'dropped': stats.sent - received,
        'p50': p50,
        'p99': p99,
        'latency_ms': latency_ms,
    }


def combine(runs: list[dict[str, Any]], mode: str) -> dict[str, Any]:
    """Rounds of one case: max mode, the best round; paced, drops summed, latencies pooled."""
    if mode == 'max':
        return max(runs, key=lambda r: r['rate'])
    latency_ms = np.concatenate([r['latency_ms'] for r in runs])
    p50, p99 = np.percentile(latency_ms, [50, 99]) if latency_ms.size else (np.nan, np.nan)
    return {
        'rate': float(np.median([r['rate'] for r in runs])),
        'sent': sum(r['sent'] for r in runs),
        'dropped': sum(r['dropped'] for r in runs),
        'p50': p50,
        'p99': p99,
    }


def run_closed_loop(
    executor: Executor, source: Source, sink: Sink, stats: Stats, duration_s: float
) -> None:
    deadline = time.monotonic() + duration_s

    def next_message() -> None:
        if time.monotonic() < deadline:
            source.publish_imu()
            stats.sent += 1

    sink.on_receive = next_message
    for _ in range(WINDOW):
        next_message()
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    sink.on_receive = None
    drain(executor)


def pace(source: Source, rate_hz: float, duration_s: float) -> int:
    """Publish Imu at ``rate_hz`` on an absolute schedule for ``duration_s``; the count sent."""
    period_ns = 1e9 / rate_hz
    start = time.perf_counter_ns()
    end = start + duration_s * 1e9
    k = 0
    while True:
        target = start + k * period_ns
        if target > end:
            return k
        wait_ns = target - time.perf_counter_ns()
        if wait_ns > 0:
            time.sleep(wait_ns / 1e9)
        source.publish_imu()
        k += 1


def serve_pacer(rate_hz: float, duration_s: float, with_temperature: bool, namespace: str) -> None:
    """Child process of paced ``--dut-process`` cases: a Source alone, printing ``sent N``."""
    context = Context()
    rclpy.init(context=context)
    source = Source(context, namespace)
    try:
        deadline = time.monotonic() + 20.0
        while source.imu_pub.get_subscription_count() == 0 or (
            with_temperature and source.temp_pub.get_subscription_count() == 0
        ):
            if time.monotonic() > deadline:
                raise SystemExit('pacer: the DUT was not discovered')
            time.sleep(0.01)
        time.sleep(1.0)  # both ends matched
        print(f'sent {pace(source, rate_hz, duration_s)}', flush=True)
    finally:
        source.destroy_node()
        rclpy.try_shutdown(context=context)


def run_paced_process(
    executor: Executor, stats: Stats, mode: str, duration_s: float, kind: str
) -> None:
    """Paced mode with the source in a third process (no GIL shared with the sink)."""
    command = [sys.executable, __file__, '--serve', 'pacer', '--namespace', NS]
    command += ['--rate', mode, '--duration', str(duration_s)]
    if kind == 'compensator':
        command.append('--with-temperature')
    pacer = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    while pacer.poll() is None:
        executor.spin_once(timeout_sec=0.05)
    out, err = pacer.communicate()
    sent = [line for line in out.decode().splitlines() if line.startswith('sent ')]
    if pacer.returncode != 0 or not sent:
        raise RuntimeError(f'pacer failed ({pacer.returncode}): {out.decode()} {err.decode()}')
    stats.sent = int(sent[-1].split()[1])
    drain(executor)


def run_open_loop(
    executor: Executor, source: Source, stats: Stats, mode: str, duration_s: float
) -> None:
    done = threading.Event()

    def publish() -> None:
        stats.sent = pace(source, float(mode), duration_s)
        done.set()

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    while not done.is_set():
        executor.spin_once(timeout_sec=0.05)
    thread.join()
    drain(executor)


def drain(executor: Executor, seconds: float = 0.5) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='3 s per case instead of 10 s')
    parser.add_argument('--duration', type=float, default=None, help='seconds per case')
    parser.add_argument('--modes', nargs='+', default=['200', '1000', '2000', 'max'])
    parser.add_argument(
        '--executor',
        choices=['single', 'events'],
        default='single',
        help='SingleThreadedExecutor (default) or rclpy.experimental.EventsExecutor',
    )
    parser.add_argument('--rounds', type=int, default=None, help='rounds (default 3)')
    parser.add_argument(
        '--dut-process', action='store_true', help='run the DUT in a process of its own'
    )
    parser.add_argument(
        '--serve', choices=['relay', 'compensator', 'pacer'], help=argparse.SUPPRESS
    )
    parser.add_argument('--namespace', default=NS, help=argparse.SUPPRESS)
    parser.add_argument('--rate', type=float, help=argparse.SUPPRESS)
    parser.add_argument('--with-temperature', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument(
        '--rest-learning', action='store_true', help='compensator with bias learning at rest on'
    )
    args = parser.parse_args()
    if args.rest_learning:
        EXTRA_PARAMETERS['rest_learning'] = True
    if args.serve == 'pacer':
        serve_pacer(args.rate, args.duration, args.with_temperature, args.namespace)
        return
    if args.serve:
        serve(args.serve, args.executor, args.namespace)
        return
    duration = args.duration or (3.0 if args.quick else 10.0)
    rounds = args.rounds or (1 if args.quick else 3)
    rmw = os.environ.get('RMW_IMPLEMENTATION', 'default')
    print(
        f'# bench_node: {rounds} x {duration:g} s per case, executor {args.executor}, '
        f'DUT in {"its own process" if args.dut_process else "this process"}, '
        f'rmw {rmw}, rest learning {"on" if args.rest_learning else "off"}; {machine()}'
    )
    runs: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for round_ in range(rounds):  # round robin, DUT order alternating: load hits both alike
        for mode in args.modes:
            kinds = ('relay', 'compensator') if round_ % 2 == 0 else ('compensator', 'relay')
            for kind in kinds:
                r = run_case(kind, mode, duration, args.executor, args.dut_process)
                runs.setdefault((kind, mode), []).append(r)
                print(
                    f'  round {round_ + 1} {mode:>5} {kind:<11} {r["rate"]:9.1f} msg/s  '
                    f'sent {r["sent"]}  dropped {r["dropped"]}  p50 {r["p50"]:.3f} ms  '
                    f'p99 {r["p99"]:.3f} ms',
                    flush=True,
                )
    results = {key: combine(value, key[1]) for key, value in runs.items()}
    rows = []
    for mode in args.modes:
        rel, comp = results['relay', mode], results['compensator', mode]
        label = 'max (closed loop)' if mode == 'max' else f'{mode} Hz'
        rows.append(
            [
                label,
                rel['rate'],
                comp['rate'],
                comp['rate'] / rel['rate'],
                f'{int(rel["dropped"])}/{int(rel["sent"])}',
                f'{int(comp["dropped"])}/{int(comp["sent"])}',
                rel['p50'],
                comp['p50'],
                comp['p50'] - rel['p50'],
                rel['p99'],
                comp['p99'],
                comp['p99'] - rel['p99'],
            ]
        )
    print()
    headers = [
        'mode',
        'relay msg/s',
        'comp msg/s',
        'comp / relay',
        'relay dropped',
        'comp dropped',
        'relay p50 ms',
        'comp p50 ms',
        'added p50 ms',
        'relay p99 ms',
        'comp p99 ms',
        'added p99 ms',
    ]
    print(table(headers, rows))
    print()
    if 'max' in args.modes:
        ratio = results['compensator', 'max']['rate'] / results['relay', 'max']['rate']
        print(f'goal compensator >= 0.8x relay max throughput: {ratio:.2f}x')
    if '2000' in args.modes:
        drops = results['compensator', '2000']['dropped']
        print(f'goal no drops at 2 kHz: compensator dropped {int(drops)}')


if __name__ == '__main__':
    main()
