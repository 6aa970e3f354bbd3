"""``fog-temp-comp simulate``: the paper's chamber runs as bags, truth ``.npz`` and manifest.

The simulator itself (:mod:`~fog_temp_comp.tools.simulate`, scipy) is imported only when
the command runs.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
import yaml

from fog_temp_comp.bag import bagio
from fog_temp_comp.core.model import coefficient_key
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools.atomic import AtomicOutputs

if TYPE_CHECKING:
    from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig


def bag_name(name: str, fmt: str) -> str:
    """File or directory name of a bag called ``name`` in format ``fmt``."""
    return name + '.bag' if fmt == 'ros1' else name


def simulate_command(
    out_dir: Path,
    *,
    fmt: str = 'mcap',
    imu_hz: float = 10.0,
    temp_hz: float = 1.0,
    realistic: bool = False,
    seed: int = 0,
    compress: bool = True,
    runs: Sequence[tuple[str, float]] | None = None,
    config: SimulationConfig | None = None,
    vehicle: dict[str, Any] | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Write the paper's chamber runs as bags plus ``<run>.truth.npz`` and ``manifest.yaml``.

    ``vehicle`` overrides :class:`SimulationConfig` fields of the vehicle (turn-on shift in
    deg/h, power-on self-heating in degC, rest/motion phases); the truth files then hold
    ``turn_on_shift_deg_h`` and ``true_rotation_rad_s`` too (the oracle: rate minus drift,
    shift and rotation is noise).
    """
    # here, not at the top: the simulator needs scipy.signal (~1 s), no other command does
    from fog_temp_comp.tools.simulate import REALISTIC, SimulationConfig, paper_plan, simulate_run
    from fog_temp_comp.tools.simulate_limits import check_rates, check_runs, check_seed

    stdout = stdout or sys.stdout
    check_seed(seed)
    if config is None:
        check_rates(imu_hz, temp_hz)
    base = REALISTIC if realistic else SimulationConfig()
    cfg = config or dataclasses.replace(base, imu_hz=imu_hz, temp_hz=temp_hz, **(vehicle or {}))
    check_rates(cfg.imu_hz, cfg.temp_hz)
    check_runs(runs or paper_plan(), cfg)  # all of them before the first is simulated
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = _manifest_to_extend(out_dir / 'manifest.yaml', _simulation_manifest(cfg, fmt, seed))
    first = len(manifest['runs'])  # runs added to a folder get seeds of their own
    with AtomicOutputs() as outputs:  # all files appear at the end, or none
        for k, (kind, setpoint) in enumerate(runs or paper_plan(), start=first):
            run = simulate_run(kind, setpoint, cfg, seed=seed * 1000 + k)
            path = out_dir / bag_name(run.name, fmt)
            bagio.write_chamber_bag(
                outputs.path(path),
                fmt,
                imu_stamps_s=run.imu_stamps_s,
                rates_rad_s=run.rates_rad_s,
                temp_stamps_s=run.temp_stamps_s,
                temperature_degC=run.temperature_degC,
                compress=compress,
            )
            truth = out_dir / f'{run.name}.truth.npz'
            _save_truth(outputs.path(truth), run)
            unit = 'degC_per_min' if kind == 'cycle' else 'degC'
            manifest['runs'].append(
                {
                    'name': run.name,
                    'kind': kind,
                    f'setpoint_{unit}': setpoint,
                    'bag': path.name,
                    'truth': truth.name,
                    'duration_s': float(run.imu_stamps_s[-1] - run.imu_stamps_s[0]),
                }
            )
            print(
                f'wrote {path} ({run.imu_stamps_s.size} Imu, '
                f'{run.temp_stamps_s.size} Temperature)',
                file=stdout,
            )
        manifest_path = outputs.path(out_dir / 'manifest.yaml', replace=True)
        manifest_path.write_text(yaml.safe_dump(manifest, sort_keys=False))
    return 0


def _manifest_to_extend(path: Path, new: dict[str, Any]) -> dict[str, Any]:
    """``new``, or the folder's manifest if it describes the same simulation (runs are added).

    A folder that holds another simulation (other rates, coefficients, seed, format, vehicle)
    is refused: one manifest describes all of a folder's runs.
    """
    if not path.exists():
        return new
    try:
        old = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f'{path}: cannot read the manifest to add runs to: {err}') from None
    if not isinstance(old, dict) or not isinstance(old.get('runs'), list):
        raise ValueError(f'{path}: not a manifest of fog-temp-comp simulate')
    differ = [key for key in new if key != 'runs' and old.get(key) != new[key]]
    if differ:
        raise ValueError(
            f'{path.parent} holds a simulation with other settings ({", ".join(differ)}): '
            'write these runs to another directory'
        )
    return old


def _simulation_manifest(cfg: SimulationConfig, fmt: str, seed: int) -> dict[str, Any]:
    """The manifest of a simulation: rates (Hz), the true coefficients and vehicle; no runs yet."""
    return {
        'description': 'synthetic thermal-chamber runs (fog_temp_comp simulate)',
        'format': fmt,
        'imu_hz': cfg.imu_hz,
        'temp_hz': cfg.temp_hz,
        'seed': seed,
        'true_coefficients': {
            axis: {
                coefficient_key(term): float(cfg.true_coefficients[i, j])
                for i, term in enumerate(cfg.terms)
            }
            for j, axis in enumerate(AXES)
        },
        'coil_lag_s': float(cfg.coil_lag_s),
        'turn_on_shift_deg_h': dict(zip(AXES, map(float, cfg.turn_on_shift_deg_h), strict=True)),
        'power_on_heating_degC': float(cfg.power_on_heating_degC),
        'motion_period_s': float(cfg.motion_period_s),
        'motion_fraction': float(cfg.motion_fraction),
        'motion_rate_deg_s': float(cfg.motion_rate_deg_s),
        'runs': [],
    }


def _save_truth(path: Path, run: SimulatedRun) -> None:
    """A run's truth (the oracle's inputs) as ``.npz``: drift deg/h, T degC, Tdot degC/min."""
    np.savez_compressed(
        path,
        imu_stamps_s=run.imu_stamps_s,
        true_drift_deg_h=run.true_drift_deg_h,
        true_temperature_degC=run.true_temperature_degC,
        true_tdot_degC_per_min=run.true_tdot_degC_per_min,
        turn_on_shift_deg_h=run.turn_on_shift_deg_h,
        true_rotation_rad_s=(
            np.zeros_like(run.rates_rad_s)
            if run.true_rotation_rad_s is None
            else run.true_rotation_rad_s
        ),
    )
