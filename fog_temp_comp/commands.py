"""The offline commands as plain functions returning an exit code (the CLI only parses)."""

from __future__ import annotations

import dataclasses
import shutil
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import yaml

from fog_temp_comp import bagio, cdr
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
                replayer = ChunkReplayer(compensator, reader, imu_name, temp_name)
                for chunk in chunked(messages, 20_000):
                    for topic, log_ns, raw in replayer.run(chunk):
                        writer.write_raw(topic or output_topic, log_ns, raw)
                        n_out += topic is None
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


def chunked(items: Iterable[Any], size: int) -> Iterator[list[Any]]:
    """Consecutive lists of at most ``size`` items."""
    chunk: list[Any] = []
    for item in items:
        chunk.append(item)
        if len(chunk) >= size:
            yield chunk
            chunk = []
    if chunk:
        yield chunk


class ChunkReplayer:
    """Feed bag messages through a compensator a chunk at a time, in their original order.

    Imu and Temperature messages of a chunk are decoded in one batch (:mod:`fog_temp_comp.cdr`),
    the compensator sees every message in bag order exactly as one at a time, and the corrected
    Imu are written by patching the raw bytes, so every other field stays bit-identical.
    """

    def __init__(self, compensator: Compensator, reader: Any, imu_topic: str, temp_topic: str):
        self.compensator = compensator
        self.ros2 = bool(reader.is2)
        self.imu_topic = imu_topic
        self.temp_topic = temp_topic
        self._seq = {
            c.id: (cdr.ros1_header_has_seq(c.msgdef.data) if not self.ros2 else False)
            for c in reader.connections
        }

    def run(self, chunk: list[tuple[Any, int, bytes]]) -> list[tuple[str | None, int, bytes]]:
        """Messages to write for ``chunk``, in order.

        Every input as (topic, log_ns, raw), each corrected Imu followed by its output with
        topic None.
        """
        imu = [k for k, (c, _, _) in enumerate(chunk) if c.topic == self.imu_topic]
        temp = [k for k, (c, _, _) in enumerate(chunk) if c.topic == self.temp_topic]
        imu_batch = self._decode([chunk[k] for k in imu], imu=True)
        temp_batch = self._decode([chunk[k] for k in temp], imu=False)
        rates = imu_batch.angular_velocity_rad_s.tolist() if imu else []
        imu_stamps = imu_batch.stamps_s.tolist() if imu else []
        temp_stamps = temp_batch.stamps_s.tolist() if temp else []
        temps = temp_batch.temperature_degC.tolist() if temp else []
        kind = {k: ('imu', j) for j, k in enumerate(imu)}
        kind.update({k: ('temp', j) for j, k in enumerate(temp)})
        corrected: list[tuple[float, float, float] | None] = []
        compensator = self.compensator
        for k in range(len(chunk)):
            what = kind.get(k)
            if what is None:
                continue
            j = what[1]
            if what[0] == 'temp':
                compensator.add_temperature(temp_stamps[j], temps[j])
            else:
                x, y, z = rates[j]
                corrected.append(compensator.correct_xyz(imu_stamps[j], x, y, z))
        keep = [j for j, c in enumerate(corrected) if c is not None]
        patched = self._patch([chunk[imu[j]] for j in keep], [corrected[j] for j in keep])
        out_of = dict(zip((imu[j] for j in keep), patched, strict=True))
        out: list[tuple[str | None, int, bytes]] = []
        for k, (conn, log_ns, raw) in enumerate(chunk):
            out.append((conn.topic, log_ns, raw))
            if k in out_of:
                out.append((None, log_ns, out_of[k]))
        return out

    def _decode(self, items: list[tuple[Any, int, bytes]], *, imu: bool) -> Any:
        if not items:
            return None
        raws = [raw for _, _, raw in items]
        if self.ros2:
            return (cdr.decode_imu_cdr if imu else cdr.decode_temperature_cdr)(raws)
        seq = self._seq[items[0][0].id]
        if imu:
            return cdr.decode_imu_ros1(raws, header_seq=seq)
        return cdr.decode_temperature_ros1(raws, header_seq=seq)

    def _patch(self, items: list[tuple[Any, int, bytes]], rates: list[Any]) -> list[bytes]:
        if not items:
            return []
        raws = [raw for _, _, raw in items]
        if self.ros2:
            return cdr.patch_imu_angular_velocity_cdr(raws, rates)
        seq = self._seq[items[0][0].id]
        return cdr.patch_imu_angular_velocity_ros1(raws, rates, header_seq=seq)


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
