"""``fleet calibrate --scheduler`` against a real ``distributed`` scheduler and workers.

The scheduler and the workers are separate processes (``python -m dask scheduler`` /
``dask worker``, on 127.0.0.1, each in its own process group), started once for the module and
always stopped; every wait is bounded.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from distributed import Client
from test_fleet import finished, simulate, table

from fog_temp_comp.tools import cli

START_TIMEOUT_S = 90
N_WORKERS = 2


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop a process group started here: SIGTERM, then SIGKILL after 10 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)


@pytest.fixture(scope='module')
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Client]]:
    """(scheduler address, a client of it) with two single-thread workers under nannies."""
    root = tmp_path_factory.mktemp('cluster')
    scheduler_file = root / 'scheduler.json'
    dask = [sys.executable, '-m', 'dask']
    procs = []
    client = None
    try:
        procs.append(
            subprocess.Popen(
                [*dask, 'scheduler', '--host', '127.0.0.1', '--port', '0', '--no-dashboard',
                 '--scheduler-file', str(scheduler_file)],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            )
        )  # fmt: skip
        deadline = time.monotonic() + START_TIMEOUT_S
        while not scheduler_file.is_file():
            assert procs[0].poll() is None, 'dask scheduler exited'
            assert time.monotonic() < deadline, 'dask scheduler did not start'
            time.sleep(0.1)
        time.sleep(0.2)  # the file is written in one go, but let it land
        address = json.loads(scheduler_file.read_text())['address']
        procs.append(
            subprocess.Popen(
                [*dask, 'worker', address, '--host', '127.0.0.1', '--nworkers', str(N_WORKERS),
                 '--nthreads', '1', '--no-dashboard', '--death-timeout', '60'],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            )
        )  # fmt: skip
        client = Client(address, timeout=START_TIMEOUT_S)
        client.wait_for_workers(N_WORKERS, timeout=START_TIMEOUT_S)
        yield address, client
    finally:
        if client is not None:
            client.close()
        for proc in reversed(procs):
            _stop(proc)


def test_fleet_calibrate_on_a_running_scheduler(
    tmp_path: Path, cluster: tuple[str, Client]
) -> None:
    address, _ = cluster
    manifest = simulate(tmp_path / 'units', 4, 0.25, seed=5)  # one unit's bag is missing
    out = tmp_path / 'out'
    argv = ['fleet', 'calibrate', str(manifest), '-o', str(out), '--scheduler', address]
    assert cli.main(argv) == 1
    rows = table(out)
    assert sorted(r['status'] for r in rows.values()) == ['failed', 'ok', 'ok', 'ok']
    for unit, row in rows.items():
        assert (out / f'{unit}.yaml').is_file() == (row['status'] == 'ok')


def test_a_killed_worker_loses_no_unit(tmp_path: Path, cluster: tuple[str, Client]) -> None:
    address, client = cluster
    manifest = simulate(tmp_path / 'units', 6, 0.0, seed=6)
    out = tmp_path / 'out'
    argv = ['fleet', 'calibrate', str(manifest), '-o', str(out), '--scheduler', address]
    status: list[int] = []
    run = threading.Thread(target=lambda: status.append(cli.main(argv)), daemon=True)
    run.start()
    pids = client.run(os.getpid)  # worker address -> process id
    killed = None
    deadline = time.monotonic() + START_TIMEOUT_S
    while killed is None and time.monotonic() < deadline and run.is_alive():
        for worker, keys in client.processing().items():
            if any(str(k).startswith('fog-calibrate-') for k in keys):
                killed = pids[worker]
                os.kill(killed, signal.SIGKILL)  # a worker process dies mid-task
                break
        time.sleep(0.02)
    run.join(timeout=180)
    assert killed is not None, 'no task was seen running'
    assert not run.is_alive(), 'fleet calibrate did not finish'
    assert status == [0]
    assert {r['status'] for r in table(out).values()} == {'ok'}
    assert len(finished(out)) == 6  # every unit done, each once
    client.wait_for_workers(N_WORKERS, timeout=START_TIMEOUT_S)  # the nanny restarted it
