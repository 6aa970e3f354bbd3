"""The offline commands as plain functions returning an exit code (the CLI only parses)."""

from __future__ import annotations

import dataclasses
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import yaml

from fog_temp_comp import bagio
from fog_temp_comp.bagio import BagError, BagWriter, read_record
from fog_temp_comp.calibration import CalibrationError, calibrate
from fog_temp_comp.coefficients import Coefficients, CoefficientsError, load, save
from fog_temp_comp.compensator import Compensator, CompensatorCounters, GuardSettings
from fog_temp_comp.denoise import DenoiseSettings
from fog_temp_comp.evaluate import format_scores, replay_record, score_record
from fog_temp_comp.simulate import SimulationConfig, paper_plan, simulate_run
from fog_temp_comp.units import AXES

#: errors that end a command with one ``ERROR:`` line and exit code 1
USER_ERRORS = (BagError, CalibrationError, CoefficientsError, FileExistsError, ValueError)


def bag_name(name: str, fmt: str) -> str:
    """File or directory name of a bag called ``name`` in format ``fmt``."""
    return name + '.bag' if fmt == 'ros1' else name


def simulate_command(
    out_dir: Path,
    *,
    fmt: str = 'mcap',
    imu_hz: float = 10.0,
    temp_hz: float = 1.0,
    seed: int = 0,
    compress: bool = True,
    runs: Sequence[tuple[str, float]] | None = None,
    config: SimulationConfig | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Write the paper's chamber runs as bags plus ``<run>.truth.npz`` and ``manifest.yaml``."""
    stdout = stdout or sys.stdout
    cfg = config or SimulationConfig(imu_hz=imu_hz, temp_hz=temp_hz)
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest: dict[str, Any] = {
        'description': 'synthetic thermal-chamber runs (fog_temp_comp simulate)',
        'format': fmt,
        'imu_hz': cfg.imu_hz,
        'temp_hz': cfg.temp_hz,
        'seed': seed,
        'true_coefficients': {
            axis: dict(
                zip(
                    ('d0_deg_h', 'dt_deg_h_per_degC', 'dtdot_deg_h_per_degC_per_min'),
                    map(float, cfg.coefficients[:, j]),
                    strict=True,
                )
            )
            for j, axis in enumerate(AXES)
        },
        'runs': [],
    }
    for k, (kind, setpoint) in enumerate(runs or paper_plan()):
        run = simulate_run(kind, setpoint, cfg, seed=seed * 1000 + k)
        path = out_dir / bag_name(run.name, fmt)
        bagio.write_chamber_bag(
            path,
            fmt,
            imu_stamps_s=run.imu_stamps_s,
            rates_rad_s=run.rates_rad_s,
            temp_stamps_s=run.temp_stamps_s,
            temperature_degC=run.temperature_degC,
            compress=compress,
        )
        truth = out_dir / f'{run.name}.truth.npz'
        np.savez_compressed(
            truth,
            imu_stamps_s=run.imu_stamps_s,
            true_drift_deg_h=run.true_drift_deg_h,
            true_temperature_degC=run.true_temperature_degC,
            true_tdot_degC_per_min=run.true_tdot_degC_per_min,
        )
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
            f'wrote {path} ({run.imu_stamps_s.size} Imu, {run.temp_stamps_s.size} Temperature)',
            file=stdout,
        )
    (out_dir / 'manifest.yaml').write_text(yaml.safe_dump(manifest, sort_keys=False))
    return 0


def calibrate_command(
    bags: Sequence[Path],
    output: Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    settings: DenoiseSettings | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Fit coefficients on ``bags`` and write them to ``output`` (YAML)."""
    stdout = stdout or sys.stdout
    settings = settings or DenoiseSettings()
    records = [read_record(b, gyro_topic=gyro_topic, temp_topic=temp_topic) for b in bags]
    coeffs = calibrate(records, settings)
    save(coeffs, output)
    model = coeffs.model
    print(
        f'fitted {", ".join(model.terms)} on {len(records)} bag(s), Tdot denoise '
        f'{settings.method}; wrote {output}',
        file=stdout,
    )
    for j, axis in enumerate(AXES):
        fit = coeffs.fit[axis]
        values = '  '.join(
            f'{t}={model.coefficients[i, j]:+.6g}' for i, t in enumerate(model.terms)
        )
        print(
            f'  {axis}: {values}  residual_std={fit["residual_std_deg_h"]:.4f} deg/h  '
            f'R2={fit["r_squared"]:.4f}',
            file=stdout,
        )
    t_range, r_range = model.temperature_range_degC, model.tdot_range_degC_per_min
    print(
        f'  calibrated range: T [{t_range.low:.2f}, {t_range.high:.2f}] degC, '
        f'Tdot [{r_range.low:.3f}, {r_range.high:.3f}] degC/min',
        file=stdout,
    )
    return 0


def compensate_command(
    in_bag: Path,
    coeffs_path: Path,
    out_bag: Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    output_topic: str = '/imu/data',
    denoise_method: str | None = None,
    guard: GuardSettings | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Replay ``in_bag`` through a :class:`Compensator`; write all inputs plus corrected Imu.

    Messages are processed in the bag's log-time order, i.e. the order a node sees on replay.
    """
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    if out_bag.exists():
        raise FileExistsError(f'{out_bag}: exists already, not overwriting')
    compensator = Compensator(coeffs.model, effective_settings(coeffs, denoise_method), guard)
    fmt = bagio.bag_format(in_bag)
    if output_topic and not output_topic.startswith('/'):
        output_topic = '/' + output_topic
    n_out = 0
    with bagio.open_bag(in_bag) as reader:
        imu_name = bagio.resolve_topic(reader, gyro_topic, bagio.IMU_TYPE, '--gyro-topic')
        temp_name = bagio.resolve_topic(reader, temp_topic, bagio.TEMPERATURE_TYPE, '--temp-topic')
        if output_topic in reader.topics:
            raise BagError(f'--output-topic {output_topic}: already in {in_bag}; choose another')
        try:
            with BagWriter(out_bag, fmt) as writer:
                for conn in reader.connections:
                    if conn.topic not in writer.topics:
                        writer.add_topic(conn.topic, conn.msgtype, like=conn)
                writer.add_topic(output_topic, bagio.IMU_TYPE)
                messages = bagio.temperature_first(reader.messages(), temp_name)
                for conn, log_ns, raw in messages:
                    writer.write_raw(conn.topic, log_ns, raw)
                    if conn.topic == temp_name:
                        msg: Any = reader.deserialize(raw, conn.msgtype)
                        compensator.add_temperature(
                            bagio.stamp_to_s(msg.header.stamp), msg.temperature
                        )
                    elif conn.topic == imu_name:
                        msg = reader.deserialize(raw, conn.msgtype)
                        w = msg.angular_velocity
                        rate = compensator.correct(
                            bagio.stamp_to_s(msg.header.stamp), (w.x, w.y, w.z)
                        )
                        if rate is None:  # duplicate stamp: dropped, counted
                            continue
                        w.x, w.y, w.z = float(rate[0]), float(rate[1]), float(rate[2])
                        writer.write(output_topic, log_ns, msg)
                        n_out += 1
        except Exception as err:
            remove_bag(out_bag)  # no half-written output
            if isinstance(err, BagError):
                raise
            raise BagError(f'{in_bag}: failed while replaying (truncated bag?): {err}') from err
    counters = compensator.status.counters
    print(
        f'wrote {out_bag}: {n_out} corrected Imu on {output_topic} '
        f'({counters.imu_uncorrected} before the first temperature passed through)',
        file=stdout,
    )
    return 0


def effective_settings(coeffs: Coefficients, denoise_method: str | None) -> DenoiseSettings:
    """The coefficients file's denoise settings, with the method overridden if given."""
    if denoise_method is None:
        return coeffs.denoise
    return dataclasses.replace(coeffs.denoise, method=denoise_method)


def remove_bag(path: Path) -> None:
    """Delete a bag file or directory if it exists."""
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


def evaluate_command(
    bags: Sequence[Path],
    coeffs_path: Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    denoise_method: str | None = None,
    guard: GuardSettings | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Print stability and range before/after compensation for each bag and axis."""
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    scores = []
    notes = []
    for bag in bags:
        record = read_record(bag, gyro_topic=gyro_topic, temp_topic=temp_topic)
        corrected, status = replay_record(
            record, coeffs, effective_settings(coeffs, denoise_method), guard
        )
        scores += score_record(bag.name, record.imu_stamps_s, record.rates_rad_s, corrected)
        notes += clamp_notes(bag.name, status.counters, coeffs)
    print(format_scores(scores), file=stdout)
    for note in notes:
        print(note, file=stdout)
    return 0


def clamp_notes(name: str, counters: CompensatorCounters, coeffs: Coefficients) -> list[str]:
    """Say when the calibrated-range guard limited the correction of a run."""
    notes = []
    total = max(counters.imu_total, 1)
    model = coeffs.model
    for count, what, rng, unit, flag in (
        (counters.imu_tdot_clamped, 'Tdot', model.tdot_range_degC_per_min, 'degC/min',
         '--extrapolate-tdot'),
        (counters.imu_temperature_clamped, 'temperature', model.temperature_range_degC, 'degC',
         None),
    ):  # fmt: skip
        if count:
            hint = f'; {flag} applies the linear term beyond it' if flag else ''
            notes.append(
                f'note: {name}: {what} left the calibrated range [{rng.low:.3g}, {rng.high:.3g}] '
                f'{unit} for {100 * count / total:.0f} % of the gyro samples and was clamped{hint}'
            )
    return notes
