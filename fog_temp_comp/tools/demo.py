"""The paper's experiment end to end: calibrate on the 0.2 degC/min cycle, judge on the others.

For each Tdot denoising method (none, IIR, wavelet) the coefficients are fitted on the training
run and every other run is replayed through the online :class:`Compensator`; the table compares
10 s bias stability and range before and after, like the paper's Tables 2 and 3.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import yaml

from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import GuardSettings
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.tools.commands import CalibrateOptions, calibrate_command, simulate_command
from fog_temp_comp.tools.simulate import TRAINING_RUN

#: pipelines compared: the paper's three (raw, IIR, wavelet Tdot) with the paper's model, then
#: this package's default (``calibrate`` with no flags: the model chosen by cross-validation)
PIPELINES: dict[str, CalibrateOptions] = {
    'none': CalibrateOptions(settings=DenoiseSettings(method='none'), terms=PAPER_TERMS),
    'iir': CalibrateOptions(settings=DenoiseSettings(method='iir'), terms=PAPER_TERMS),
    'wavelet': CalibrateOptions(settings=DenoiseSettings(method='wavelet'), terms=PAPER_TERMS),
    'default': CalibrateOptions(),
}
METHODS = tuple(PIPELINES)
HEADERS = {'none': 'none', 'iir': 'IIR', 'wavelet': 'wavelet', 'default': 'default'}
#: the paper judges a model fitted at 0.2 degC/min on faster cycles: Tdot is extrapolated (the
#: default guard)
PAPER_PROTOCOL = GuardSettings()


#: the files the demo writes into its output folder (and ``bags/``, simulated when not given)
DEMO_FILES = frozenset({*(f'coeffs_{m}.yaml' for m in METHODS), 'table.md'})


def clear_demo_output(out_dir: Path) -> list[str]:
    """Remove what an earlier demo wrote into ``out_dir``, so that it runs again; the names.

    Only a folder that holds nothing but the demo's files (:data:`DEMO_FILES`, a simulated
    ``bags/`` folder, which is kept and reused) is cleared; anything else in it is refused
    with a FileExistsError, nothing removed.
    """
    if not out_dir.exists():
        return []
    if not out_dir.is_dir():
        raise FileExistsError(f'{out_dir}: exists already and is not a folder, not overwriting')
    names = {p.name for p in out_dir.iterdir()}
    others = sorted(names - DEMO_FILES - {'bags'})
    if others:
        shown = ', '.join(others[:3]) + (', ...' if len(others) > 3 else '')
        raise FileExistsError(
            f'{out_dir}: not a demo output folder (holds {shown}), not overwriting; '
            'choose another --out'
        )
    removed = sorted(names & DEMO_FILES)
    for name in removed:
        (out_dir / name).unlink()
    return removed


@dataclass(frozen=True)
class DemoRow:
    """10 s scores of one run and axis: before, and after with each method (deg/h)."""

    run: str
    axis: str
    stability_before: float
    stability_after: dict[str, float]
    range_before: float
    range_after: dict[str, float]


def run_demo(bags_dir: Path, out_dir: Path, *, stdout: TextIO | None = None) -> list[DemoRow]:
    """Calibrate with each method on the training run and score all other runs at 10 s."""
    stdout = stdout or sys.stdout
    manifest = yaml.safe_load((bags_dir / 'manifest.yaml').read_text())
    runs = {r['name']: bags_dir / r['bag'] for r in manifest['runs']}
    if TRAINING_RUN not in runs:
        raise ValueError(f'{bags_dir}/manifest.yaml has no {TRAINING_RUN} run to calibrate on')
    out_dir.mkdir(parents=True, exist_ok=True)
    coeffs = {}
    for method in METHODS:
        path = out_dir / f'coeffs_{method}.yaml'
        calibrate_command([runs[TRAINING_RUN]], path, options=PIPELINES[method], stdout=stdout)
        coeffs[method] = load(path)
    rows = []
    for name, bag in runs.items():
        if name == TRAINING_RUN:
            continue
        record = read_record(bag)
        per_method = {
            m: score_record(
                name,
                record.imu_stamps_s,
                record.rates_rad_s,
                compensate_record(record, coeffs[m], guard=PAPER_PROTOCOL),
                taus_s=(10.0,),
            )
            for m in METHODS
        }
        for j, base in enumerate(per_method[METHODS[0]]):
            rows.append(
                DemoRow(
                    run=name,
                    axis=base.axis,
                    stability_before=base.stability_before_deg_h,
                    stability_after={m: per_method[m][j].stability_after_deg_h for m in METHODS},
                    range_before=base.range_before_deg_h,
                    range_after={m: per_method[m][j].range_after_deg_h for m in METHODS},
                )
            )
    return rows


def format_table(rows: list[DemoRow]) -> str:
    """Markdown table of the demo (deg/h)."""
    names = ' | '.join(HEADERS[m] for m in METHODS)
    head = f'| run | axis | stability before | {names} | range before | {names} |'
    lines = [head, '|' + '---|' * (4 + 2 * len(METHODS))]
    for r in rows:
        stab = ' | '.join(f'{r.stability_after[m]:.4f}' for m in METHODS)
        rng = ' | '.join(f'{r.range_after[m]:.3f}' for m in METHODS)
        lines.append(
            f'| {r.run} | {r.axis} | {r.stability_before:.4f} | {stab} '
            f'| {r.range_before:.3f} | {rng} |'
        )
    return '\n'.join(lines)


def demo_command(*, bags_dir: Path | None, out_dir: Path, stdout: TextIO | None = None) -> int:
    """Run the demo; exit code 1 if compensation fails to improve any cycle run's stability.

    The demo's own earlier output in ``out_dir`` is replaced (:func:`clear_demo_output`).
    """
    stdout = stdout or sys.stdout
    if clear_demo_output(out_dir):
        print(f"replacing the demo's earlier output in {out_dir}", file=stdout)
    if bags_dir is None:
        bags_dir = out_dir / 'bags'
        if not (bags_dir / 'manifest.yaml').exists():
            print(f"simulating the paper's runs into {bags_dir} ...", file=stdout)
            simulate_command(bags_dir, imu_hz=0.1, temp_hz=0.5, realistic=True, stdout=stdout)
    rows = run_demo(bags_dir, out_dir, stdout=stdout)
    table = format_table(rows)
    (out_dir / 'table.md').write_text(table + '\n')
    print(
        '\n10 s bias stability and range (deg/h), before and after compensation with each '
        'Tdot denoising method\n(calibrated on ' + TRAINING_RUN + '; online compensator):\n',
        file=stdout,
    )
    print(table, file=stdout)
    failed = False
    for method in ('wavelet', 'default'):
        worse = [
            (r.run, r.axis)
            for r in rows
            if r.run.startswith('cycle') and r.stability_after[method] >= r.stability_before
        ]
        if worse:
            failed = True
            print(f'\nFAIL: {method} did not improve 10 s stability on {worse}', file=stdout)
        else:
            print(
                f'OK: {method} improves 10 s bias stability on every cycle run and axis',
                file=stdout,
            )
    return 1 if failed else 0
