"""Default ``calibrate`` (model chosen by cross-validation) on an 18 h chamber run: wall time.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/bench_choice.py [--temp-hz 1 10] [--rounds 3] [--plant 100]

The run is the 0.2 degC/min cycle of a randomly drawn plant (:mod:`fog_temp_comp.tools.plants`,
seed 100, its sensor behind the coil; ``--plant 105``: ahead of it, a coil lag chosen) between
-40 and 60 degC with 1 h holds (about 18 h), gyro 2 Hz, written as an MCAP bag.
Side by side, in fresh processes, each round times:

- ``rosbags read``: ``AnyReader.messages()`` + ``deserialize`` of every message (the floor a
  user's own script would pay);
- ``calibrate``: ``fog-temp-comp calibrate BAG -o C.yaml --quiet`` as a user runs it (start-up,
  reading, the sensor measurement, 752 candidates cross-validated, the refinement, the fit).

The fastest round of each is shown. ``--jitter-s`` adds Gaussian jitter to every stamp (a
driver that stamps on receipt: the filters then see a different interval at every sample).
``--temp-noise-quanta 0.05`` makes the sensor quiet, so ``calibrate`` fits its noise before
quantization by likelihood (the slowest case of the quantized-likelihood step).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fog_temp_comp.bag.bagio import write_chamber_bag
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import simulate_run

READ = """
import sys
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
store = get_typestore(Stores.ROS2_JAZZY)
with AnyReader([__import__('pathlib').Path(sys.argv[1])], default_typestore=store) as r:
    for c, t, raw in r.messages():
        r.deserialize(raw, c.msgtype)
"""


def jittered(stamps_s: np.ndarray, jitter_s: float, seed: int) -> np.ndarray:
    """Stamps plus Gaussian jitter of ``jitter_s`` s (a driver's receive-time stamps), sorted."""
    if jitter_s == 0:
        return stamps_s
    return np.sort(stamps_s + np.random.default_rng(seed).normal(0.0, jitter_s, stamps_s.size))


def make_bag(
    directory: Path,
    temp_hz: float,
    jitter_s: float = 0.0,
    noise_quanta: float | None = None,
    plant: int = 100,
) -> tuple[Path, float]:
    """Write the run; return the bag and its length in hours.

    ``noise_quanta``: the temperature sensor's noise in its steps (None: the plant's).
    """
    cfg = dataclasses.replace(draw_plant(plant), temp_hz=temp_hz, cycle_soak_s=3600.0)
    if noise_quanta is not None:
        cfg = dataclasses.replace(cfg, temp_noise_degC=noise_quanta * cfg.temp_quantum_degC)
    run = simulate_run('cycle', 0.2, cfg, seed=0)
    path = directory / f'cycle_{temp_hz:g}hz_{jitter_s:g}s'
    write_chamber_bag(
        path,
        'mcap',
        imu_stamps_s=jittered(run.imu_stamps_s, jitter_s, 1),
        rates_rad_s=run.rates_rad_s,
        temp_stamps_s=jittered(run.temp_stamps_s, jitter_s, 2),
        temperature_degC=run.temperature_degC,
    )
    hours = (run.imu_stamps_s[-1] - run.imu_stamps_s[0]) / 3600.0
    return path, hours


def timed(argv: list[str]) -> float:
    """Wall time of a subprocess, s."""
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--temp-hz', type=float, nargs='+', default=[1.0, 10.0])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument(
        '--jitter-s',
        type=float,
        nargs='+',
        default=[0.0, 0.001],
        help="std of the stamps' jitter, s (0: a regular clock)",
    )
    parser.add_argument(
        '--temp-noise-quanta',
        type=float,
        help="the temperature sensor's noise in quantization steps (default: the plant's 0.34, "
        'a dithering sensor; below 0.3 calibrate fits it by likelihood)',
    )
    parser.add_argument('--plant', type=int, default=100, help='the drawn plant (seed)')
    args = parser.parse_args(argv)
    tool = str(Path(sys.executable).with_name('fog-temp-comp'))
    print('| temperature | stamp jitter | run | rosbags read s | calibrate s | ratio |')
    print('|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as tmp:
        for hz, jitter in itertools.product(args.temp_hz, args.jitter_s):
            bag, hours = make_bag(Path(tmp), hz, jitter, args.temp_noise_quanta, args.plant)
            out = Path(tmp) / 'c.yaml'
            read, cal = [], []
            for _ in range(args.rounds):
                read.append(timed([sys.executable, '-c', READ, str(bag)]))
                out.unlink(missing_ok=True)  # calibrate does not overwrite
                cal.append(timed([tool, 'calibrate', str(bag), '-o', str(out), '--quiet']))
            r, c = min(read), min(cal)
            print(
                f'| {hz:g} Hz | {jitter * 1e3:g} ms | {hours:.1f} h, gyro 2 Hz | {r:.1f} | '
                f'{c:.1f} | {c / r:.2f} |'
            )
    print('\n(fastest of the rounds; 2-core VM, shared: read the ratio)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
