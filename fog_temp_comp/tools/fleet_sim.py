"""Simulated fleets: units of one gyro model drawn from a population, some deliberately faulty.

:func:`draw_unit` spreads the base configuration's coefficients and sensor-to-coil lag from
unit to unit (:data:`SPREAD`); :func:`simulate_fleet` writes one chamber cycle per unit and
``fleet.yaml``, the manifest of ``fog-temp-comp fleet calibrate``, plus ``population.yaml``
with each unit's true coefficients and fault. Faults (:data:`FAULTS`, in turn):

- ``missing``: the manifest names a bag that was never written;
- ``damaged``: the bag's data file is zeroed after its first 16 bytes (nothing to recover:
  a cut file would be read as far as intact);
- ``short``: the run stops 5 min into the first ramp (too small a swing);
- ``bad_coil``: a unit that calibrates but whose Tdot coefficient is 3 times the fleet's.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import yaml

from fog_temp_comp.bag import bagio
from fog_temp_comp.core.model import coefficient_key
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools.simulate import REALISTIC, SimulatedRun, SimulationConfig, simulate_run
from fog_temp_comp.tools.simulate_limits import check_rates, check_runs, check_seed

FAULTS = ('missing', 'damaged', 'short', 'bad_coil')
#: unit-to-unit spread: d0 (deg/h), dt (deg/h/degC) std; dtdot, T^2, coil lag relative std
SPREAD = {'d0_deg_h': 1.0, 'dt_deg_h_per_degC': 1e-3, 'dtdot': 0.08, 't2': 0.2, 'coil_lag': 0.15}
#: a short run stops this long (s) after the first ramp starts: far too small a swing
SHORT_RUN_RAMP_S = 300.0


def draw_unit(base: SimulationConfig, rng: np.random.Generator) -> SimulationConfig:
    """One unit of the population around ``base``."""
    c = np.array(base.coefficients, dtype=np.float64)
    c = c + np.stack(
        [
            rng.normal(0.0, SPREAD['d0_deg_h'], 3),
            rng.normal(0.0, SPREAD['dt_deg_h_per_degC'], 3),
            c[2] * rng.normal(0.0, SPREAD['dtdot'], 3),
        ]
    )
    t2 = np.asarray(base.t2_coefficients) * (1 + rng.normal(0.0, SPREAD['t2'], 3))
    lag = base.coil_lag_s * max(0.2, 1 + rng.normal(0.0, SPREAD['coil_lag']))
    t2_x, t2_y, t2_z = (float(v) for v in t2)
    return dataclasses.replace(
        base, coefficients=c, t2_coefficients=(t2_x, t2_y, t2_z), coil_lag_s=lag
    )


def fault_plan(n_units: int, faulty_fraction: float) -> list[str]:
    """The fault of each unit ('' for a good one), spread evenly through the fleet."""
    if not 0 <= faulty_fraction <= 1:
        raise ValueError(f'--faulty-fraction {faulty_fraction}: must be within [0, 1]')
    n_faulty = round(n_units * faulty_fraction)
    plan = [''] * n_units
    for k in range(n_faulty):
        plan[(2 * k + 1) * n_units // (2 * n_faulty)] = FAULTS[k % len(FAULTS)]
    return plan


def simulate_fleet_command(
    out_dir: Path,
    n_units: int,
    *,
    fmt: str = 'mcap',
    imu_hz: float = 1.0,
    temp_hz: float = 1.0,
    seed: int = 0,
    faulty_fraction: float = 0.1,
    base: SimulationConfig | None = None,
    cycle_degC_per_min: float = 1.0,
    options: dict[str, Any] | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Write ``n_units`` units (one cycle each), ``fleet.yaml`` and ``population.yaml``.

    ``options`` go to the manifest's ``options`` (``calibrate`` flags for every unit).
    """
    stdout = stdout or sys.stdout
    if n_units < 1:
        raise ValueError(f'--fleet {n_units}: must be >= 1')
    check_seed(seed)
    check_rates(imu_hz, temp_hz)
    base = base or dataclasses.replace(REALISTIC, imu_hz=imu_hz, temp_hz=temp_hz)
    check_runs([('cycle', cycle_degC_per_min)], base)
    rng = np.random.default_rng((seed, 14))
    out_dir.mkdir(parents=True, exist_ok=True)
    units: dict[str, Any] = {}
    truth: dict[str, Any] = {}
    for k, fault in enumerate(fault_plan(n_units, faulty_fraction)):
        unit = f'SN{k + 1:04d}'
        cfg = draw_unit(base, rng)
        if fault == 'bad_coil':
            cfg = dataclasses.replace(cfg, coefficients=cfg.coefficients * [[1], [1], [3]])
        run = simulate_run('cycle', cycle_degC_per_min, cfg, seed=seed * 100_000 + k)
        if fault == 'short':
            run = cut_run(run, cfg.cycle_soak_s / 2 + SHORT_RUN_RAMP_S)
        bag = Path(unit) / (run.name + ('.bag' if fmt == 'ros1' else ''))
        if fault != 'missing':
            _write(out_dir / bag, fmt, run)
        if fault == 'damaged':
            _damage(out_dir / bag)
        units[unit] = {'bags': [str(bag)]}
        truth[unit] = {
            'fault': fault or 'none',
            'coil_lag_s': float(cfg.coil_lag_s),
            'true_coefficients': {
                axis: {
                    coefficient_key(t): float(cfg.true_coefficients[i, j])
                    for i, t in enumerate(cfg.terms)
                }
                for j, axis in enumerate(AXES)
            },
        }
    manifest: dict[str, Any] = {'description': f'simulated fleet of {n_units} units (seed {seed})'}
    manifest.update({'options': options} if options else {})
    manifest['units'] = units
    (out_dir / 'fleet.yaml').write_text(yaml.safe_dump(manifest, sort_keys=False))
    (out_dir / 'population.yaml').write_text(yaml.safe_dump(truth, sort_keys=False))
    faulty = {u: t['fault'] for u, t in truth.items() if t['fault'] != 'none'}
    which = ': ' + ', '.join(f'{u} {f}' for u, f in faulty.items()) if faulty else ''
    print(
        f'wrote {n_units} units to {out_dir} ({len(faulty)} faulty{which}); manifest '
        f'{out_dir / "fleet.yaml"}',
        file=stdout,
    )
    return 0


def short_cycle(base: SimulationConfig, hours: float) -> tuple[SimulationConfig, float]:
    """A full-range chamber cycle compressed into ``hours``: the short run for a fleet prior.

    The cycle of :func:`~fog_temp_comp.tools.simulate.chamber_profile` (start, high, low,
    start; half a soak at each end, a soak at each extreme) with soaks of ``hours / 8`` (at
    most 1 h) and the ramp rate that fits the rest:
    every temperature of the cycle, ramps of both signs. Returns the configuration (soaks
    changed) and the rate, degC/min, for ``simulate_run('cycle', rate, cfg)``.
    """
    soak_s = min(3600.0, hours * 3600.0 / 8)
    swing_degC = (
        abs(base.high_degC - base.start_degC)
        + abs(base.high_degC - base.low_degC)
        + abs(base.start_degC - base.low_degC)
    )
    ramp_min = (hours * 3600.0 - 3 * soak_s) / 60.0
    if not ramp_min > 0:
        raise ValueError(f'a cycle of {hours} h has no time left for its ramps')
    return dataclasses.replace(base, cycle_soak_s=soak_s), swing_degC / ramp_min


def cut_run(run: SimulatedRun, duration_s: float) -> SimulatedRun:
    """The first ``duration_s`` seconds of ``run`` (a chamber run stopped early)."""
    return run.select(
        run.imu_stamps_s < run.imu_stamps_s[0] + duration_s,
        run.temp_stamps_s < run.temp_stamps_s[0] + duration_s,
    )


def _write(path: Path, fmt: str, run: SimulatedRun) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    bagio.write_chamber_bag(
        path,
        fmt,
        imu_stamps_s=run.imu_stamps_s,
        rates_rad_s=run.rates_rad_s,
        temp_stamps_s=run.temp_stamps_s,
        temperature_degC=run.temperature_degC,
    )


def _damage(path: Path) -> None:
    """Zero the bag's largest file after its first 16 bytes (a disk that lost the data)."""
    files = [p for p in path.rglob('*') if p.is_file()] if path.is_dir() else [path]
    data = max(files, key=lambda p: p.stat().st_size)
    size = data.stat().st_size
    data.write_bytes(data.read_bytes()[:16] + bytes(size - 16))
