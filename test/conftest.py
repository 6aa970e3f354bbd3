"""Shared fixtures: small simulated chamber runs, coefficient files, an in-process ROS context."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest

from fog_temp_comp.tools.simulate import SimulatedRun, simulate_run

from simdata import SHORT_CHAMBER

# keep this test run's DDS traffic to itself: its own domain, discovery on this host only; each
# pytest-xdist worker (gw0, gw1, ...: they inherit the controller's environment) its own
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
if os.environ.get('PYTEST_XDIST_WORKER', '').startswith('gw'):
    _worker = int(os.environ['PYTEST_XDIST_WORKER'][2:])
    os.environ['ROS_DOMAIN_ID'] = str(1 + (int(os.environ['ROS_DOMAIN_ID']) + _worker) % 100)
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


@pytest.fixture(scope='session')
def short_cycle() -> SimulatedRun:
    """0.5 degC/min cycle between 10 and 30 degC (about 2.3 h)."""
    return simulate_run('cycle', 0.5, SHORT_CHAMBER, seed=11)


@pytest.fixture(scope='session')
def short_cycle_fast() -> SimulatedRun:
    """1.0 degC/min cycle between 10 and 30 degC (held-out run)."""
    return simulate_run('cycle', 1.0, SHORT_CHAMBER, seed=12)


@pytest.fixture()
def rng() -> np.random.Generator:
    """Seeded generator."""
    return np.random.default_rng(1234)


@pytest.fixture()
def ros_context() -> Iterator[object]:
    """An initialised rclpy context, shut down after the test (rclpy's own test pattern)."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)
