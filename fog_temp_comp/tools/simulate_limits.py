"""What ``simulate`` accepts: rates, setpoints, seeds and run sizes, checked before any run.

Each bound is one ``ERROR:`` line naming its option, before anything is simulated: a rate of
``inf`` or ``1e9`` Hz would otherwise overflow or ask for terabytes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the simulator's import takes 0.7 s: not for the parser's help texts
    from fog_temp_comp.tools.simulate import SimulationConfig

__all__ = [
    'CYCLE_RANGE_DEGC_PER_MIN',
    'MAX_MESSAGES_PER_RUN',
    'MAX_RATE_HZ',
    'SOAK_RANGE_DEGC',
    'check_rates',
    'check_runs',
    'check_seed',
]

#: the highest gyro or temperature rate (Hz): a FOG's fastest output
MAX_RATE_HZ = 10_000.0
#: gyro plus temperature messages of one run at most (~3.5 GB of arrays while simulating)
MAX_MESSAGES_PER_RUN = 20_000_000
#: soak setpoints (degC): a thermal chamber's reach, around the simulated -40..60 degC cycles
SOAK_RANGE_DEGC = (-60.0, 100.0)
#: cycle rates (degC/min): from a slow chamber ramp to a fast one
CYCLE_RANGE_DEGC_PER_MIN = (0.01, 20.0)


def check_seed(seed: int) -> None:
    """Raise ValueError naming ``--seed`` unless it is >= 0 (numpy's seeds)."""
    if seed < 0:
        raise ValueError(f'--seed {seed}: must be >= 0')


def check_rates(imu_hz: float, temp_hz: float) -> None:
    """Raise ValueError naming the option unless each rate is in (0, :data:`MAX_RATE_HZ`] Hz."""
    for flag, hz in (('--imu-hz', imu_hz), ('--temp-hz', temp_hz)):
        if not 0.0 < hz <= MAX_RATE_HZ:  # NaN and inf too
            raise ValueError(f'{flag} {hz:g}: must be within (0, {MAX_RATE_HZ:g}] Hz')


def check_runs(runs: Sequence[tuple[str, float]], cfg: SimulationConfig) -> None:
    """Raise ValueError naming ``--runs`` for a run out of bounds, or given twice.

    Soak setpoints within :data:`SOAK_RANGE_DEGC`, cycle rates within
    :data:`CYCLE_RANGE_DEGC_PER_MIN`, at most :data:`MAX_MESSAGES_PER_RUN` messages per run
    at ``cfg``'s rates.
    """
    from fog_temp_comp.tools.simulate import chamber_profile, run_name

    names: set[str] = set()
    for kind, setpoint in runs:
        low, high = SOAK_RANGE_DEGC if kind == 'soak' else CYCLE_RANGE_DEGC_PER_MIN
        if not low <= setpoint <= high:
            what = 'a soak at' if kind == 'soak' else 'a cycle at'
            unit = 'degC' if kind == 'soak' else 'degC/min'
            raise ValueError(
                f'--runs {kind}:{setpoint:g}: {what} {setpoint:g} {unit}; '
                f'allowed {low:g}..{high:g} {unit}'
            )
        name = run_name(kind, setpoint)
        if name in names:
            raise ValueError(f'--runs: {name} given twice (each run is written once)')
        names.add(name)
        duration_s = float(chamber_profile(kind, setpoint, cfg)[0][-1])
        count = int(duration_s * cfg.imu_hz) + int(duration_s * cfg.temp_hz)
        if count > MAX_MESSAGES_PER_RUN:
            most = MAX_MESSAGES_PER_RUN / duration_s
            raise ValueError(
                f'{name}: {count:,} messages ({duration_s:,.0f} s at --imu-hz {cfg.imu_hz:g} '
                f'and --temp-hz {cfg.temp_hz:g}), at most {MAX_MESSAGES_PER_RUN:,} per run: '
                f'lower the rates (together at most {most:.3g} Hz for this run)'
            )
