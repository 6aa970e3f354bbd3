"""The offline commands as plain functions returning an exit code (the CLI only parses)."""

from __future__ import annotations

import dataclasses
import shutil
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import yaml

from fog_temp_comp.bag import bagio, cdr
from fog_temp_comp.bag.bagio import BagError, BagWriter
from fog_temp_comp.bag.reduce import reduce_record
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.calibration import CalibrationError, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load, save
from fog_temp_comp.core.compensator import Compensator, CompensatorCounters, GuardSettings
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.core.earth import earth_rate_body_deg_h, parse_orientation, remove_earth_rate
from fog_temp_comp.core.evaluate import format_scores, replay_record, score_record
from fog_temp_comp.core.fitstats import format_fits
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, coefficient_key
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.selection import default_candidates, format_results, select_and_calibrate
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools.simulate import REALISTIC, SimulationConfig, paper_plan, simulate_run

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
    realistic: bool = False,
    seed: int = 0,
    compress: bool = True,
    runs: Sequence[tuple[str, float]] | None = None,
    config: SimulationConfig | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Write the paper's chamber runs as bags plus ``<run>.truth.npz`` and ``manifest.yaml``."""
    stdout = stdout or sys.stdout
    base = REALISTIC if realistic else SimulationConfig()
    cfg = config or dataclasses.replace(base, imu_hz=imu_hz, temp_hz=temp_hz)
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest: dict[str, Any] = {
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


@dataclass(frozen=True)
class CalibrateOptions:
    """Everything ``fog-temp-comp calibrate`` can be told (units in the names)."""

    gyro_topic: str | None = None
    temp_topic: str | None = None
    temp_field: str | None = None
    time_source: str = 'header'
    settings: DenoiseSettings = RECOMMENDED_SETTINGS
    #: model terms; None (the default) lets calibrate choose the pipeline by cross-validation
    terms: tuple[str, ...] | None = None
    fit_coil_lag: bool = False
    online_tdot: bool = False
    hac_lag: int | None = None
    latitude_deg: float | None = None
    axes_orientation: str | None = None
    no_constant: bool = False
    heldout: tuple[Path, ...] = ()
    leave_one_run_out: bool = False
    #: keep the simplest candidate within this fraction of the best score
    tolerance: float = 0.02
    validate: tuple[Path, ...] = ()
    report_dir: Path | None = None
    clamp_tdot: bool = False
    quiet: bool = True
    #: a fleet prior YAML (``fleet prior``): fit toward it (:mod:`fog_temp_comp.core.prior`)
    prior: Path | None = None


def calibrate_command(
    bags: Sequence[Path],
    output: Path,
    *,
    options: CalibrateOptions | None = None,
    settings: DenoiseSettings | None = None,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    stdout: TextIO | None = None,
) -> int:
    """Fit coefficients on ``bags`` and write them to ``output`` (YAML).

    Training bags are streamed and reduced to the Tdot grid (bounded memory); held-out and
    validation bags are replayed through the compensator at full rate.
    """
    stdout = stdout or sys.stdout
    if not output.parent.is_dir():
        raise ValueError(f'-o {output}: directory {output.parent} does not exist')
    opt = options or CalibrateOptions()
    if opt.terms is not None and not opt.terms:
        raise ValueError('--terms: give at least one model term')
    opt = dataclasses.replace(
        opt,
        settings=settings or opt.settings,
        gyro_topic=gyro_topic or opt.gyro_topic,
        temp_topic=temp_topic or opt.temp_topic,
    )
    guard = GuardSettings(clamp_tdot=opt.clamp_tdot)
    read = dict(
        gyro_topic=opt.gyro_topic,
        temp_topic=opt.temp_topic,
        temp_field=opt.temp_field,
        time_source=opt.time_source,
        quiet=opt.quiet,
    )
    earth, provenance = _earth_correction(opt)
    period = opt.settings.tdot_period_s
    records = [earth(reduce_record(b, period, **read)) for b in bags]  # type: ignore[arg-type]
    if opt.prior is not None and (opt.terms or opt.fit_coil_lag or opt.heldout):
        raise ValueError('--prior sets the terms and Tdot settings; drop --terms/--fit-coil-lag')
    automatic = (
        opt.terms is None
        and not opt.fit_coil_lag
        and not opt.online_tdot
        and not opt.leave_one_run_out
        and opt.settings.method == 'kalman'
    )
    if opt.prior is not None:
        from fog_temp_comp.core import prior

        result = prior.calibrate_with_prior(
            records, prior.load_prior(opt.prior), provenance=provenance
        )
        print(prior.format_prior_fit(result), file=stdout)
    elif automatic:
        from fog_temp_comp.core import model_choice

        heldout_records = [earth(read_record(b, **read)) for b in opt.heldout]  # type: ignore[arg-type]
        result, cv_scores, cv_chosen = model_choice.choose_and_calibrate(
            records,
            opt.settings,
            heldout=heldout_records,
            tolerance=opt.tolerance,
            hac_lag=opt.hac_lag,
            provenance=provenance,
        )
        print(model_choice.format_scores(cv_scores, cv_chosen), file=stdout)
    elif opt.heldout or opt.leave_one_run_out:
        heldout = [earth(read_record(b, **read)) for b in opt.heldout] or None  # type: ignore[arg-type]
        candidates = default_candidates(opt.settings)
        coeffs, chosen, results = select_and_calibrate(
            candidates,
            records,
            heldout,
            guard=guard,
            tolerance=opt.tolerance,
        )
        print(format_results(results, chosen), file=stdout)
        candidate = chosen.candidate
        result = calibrate_detailed(
            records,
            coeffs.denoise,
            terms=candidate.terms,
            online_tdot=candidate.online_tdot,
            hac_lag=opt.hac_lag,
            provenance={**provenance, 'selection': coeffs.provenance.get('selection')},
        )
    else:
        result = calibrate_detailed(
            records,
            opt.settings,
            terms=opt.terms or PAPER_TERMS,
            fit_coil_lag=opt.fit_coil_lag,
            online_tdot=opt.online_tdot,
            hac_lag=opt.hac_lag,
            provenance=provenance,
        )
    coeffs = result.coefficients
    if opt.no_constant:
        coeffs = _without_constant(coeffs)
    save(coeffs, output)
    model = coeffs.model
    lag = coeffs.denoise.coil_lag_s
    print(
        f'fitted {", ".join(model.terms)} on {len(records)} bag(s), Tdot estimator '
        f'{coeffs.denoise.method}'
        + (f', coil lag {lag:.0f} s' if lag else '')
        + f'; wrote {output}',
        file=stdout,
    )
    for line in format_fits(result.fits):
        print('  ' + line, file=stdout)
    t_range, r_range = model.temperature_range_degC, model.tdot_range_degC_per_min
    print(
        f'  calibrated range: T [{t_range.low:.2f}, {t_range.high:.2f}] degC, '
        f'Tdot [{r_range.low:.3f}, {r_range.high:.3f}] degC/min',
        file=stdout,
    )
    for warning in result.warnings:
        print(f'WARNING: {warning}', file=stdout)
    runs = []
    if opt.validate:
        scores = []
        notes = []
        for bag in opt.validate:
            record = earth(read_record(bag, **read))  # type: ignore[arg-type]
            corrected, status = replay_record(record, coeffs, guard=guard)
            scores += score_record(bag.name, record.imu_stamps_s, record.rates_rad_s, corrected)
            notes += clamp_notes(bag.name, status.counters, coeffs)
            runs.append((bag.name, record, corrected))
        print('\nheld-out validation:', file=stdout)
        print(format_scores(scores), file=stdout)
        for note in notes:
            print(note, file=stdout)
    if opt.report_dir is not None:
        from fog_temp_comp.tools.report import (  # matplotlib only when asked
            ReportRun,
            write_report,
        )

        if not runs:  # no validation bags: show the training runs
            for record in records:
                corrected, _ = replay_record(record, coeffs, guard=guard)
                runs.append((f'{record.path.name} (training)', record, corrected))
        scores = []
        report_runs = []
        for name, record, corrected in runs:
            scores += score_record(name, record.imu_stamps_s, record.rates_rad_s, corrected)
            report_runs.append(
                ReportRun(name, record.imu_stamps_s, record.rates_rad_s, corrected,
                          record.temp_stamps_s, record.temperature_degC)
            )  # fmt: skip
        index = write_report(
            opt.report_dir,
            table=result.table,
            model=coeffs.model,
            fits=result.fits,
            runs=report_runs,
            scores=scores,
            warnings=result.warnings,
            context={
                'bags': ', '.join(str(b) for b in bags),
                'Tdot estimator': coeffs.denoise.method,
                'Earth rate': str(provenance.get('earth_rate', 'not removed')),
            },
        )
        print(f'report: {index}', file=stdout)
    return 0


def _earth_correction(
    opt: CalibrateOptions,
) -> tuple[Callable[[ChamberRecord], ChamberRecord], dict[str, Any]]:
    """Function removing the Earth-rate projection from a record, and its provenance."""
    if opt.latitude_deg is None:
        if opt.axes_orientation is not None:
            raise ValueError('--axes-orientation needs --latitude-deg')
        return (lambda record: record), {}
    if opt.axes_orientation is None:
        raise ValueError(
            '--latitude-deg needs --axes-orientation (the sensor axes in ENU, e.g. enu, ned, '
            'a quaternion x,y,z,w or a 3x3 matrix): a wrong default would shift D0 silently'
        )
    rotation = parse_orientation(opt.axes_orientation)
    lat = opt.latitude_deg
    body = earth_rate_body_deg_h(lat, rotation)
    provenance = {
        'earth_rate': {
            'latitude_deg': lat,
            'axes_orientation': opt.axes_orientation,
            'removed_deg_h': [float(v) for v in body],
        }
    }
    return (lambda record: remove_earth_rate(record, lat, rotation)), provenance


def _without_constant(coeffs: Coefficients) -> Coefficients:
    """The model without its constant term (ArduPilot style: the offset comes from elsewhere)."""
    model = coeffs.model
    if 'const' not in model.terms:
        return coeffs
    keep = [i for i, t in enumerate(model.terms) if t != 'const']
    d0 = coefficient_key('const')
    fit = {
        axis: {
            key: (
                {k: v for k, v in value.items() if k != d0} if isinstance(value, dict) else value
            )
            for key, value in entry.items()
        }
        if isinstance(entry, dict)
        else entry
        for axis, entry in coeffs.fit.items()
    }
    reduced = DriftModel(
        tuple(model.terms[i] for i in keep),
        model.coefficients[keep],
        model.temperature_range_degC,
        model.tdot_range_degC_per_min,
    )
    return dataclasses.replace(coeffs, model=reduced, fit=fit)


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
                imu_conn = next(c for c in reader.connections if c.topic == imu_name)
                # ROS 1: the corrected messages keep the input's layout (Header with seq)
                writer.add_topic(
                    output_topic, bagio.IMU_TYPE, like=imu_conn if fmt == 'ros1' else None
                )
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

    Imu and Temperature messages of a chunk are decoded in one batch
    (:mod:`~fog_temp_comp.bag.cdr`), the compensator sees every message in bag order exactly as
    one at a time, and the corrected Imu are written by patching the raw bytes, so every other
    field stays bit-identical.
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
            return (cdr.decode_imu_rates_cdr if imu else cdr.decode_temperature_cdr)(raws)
        seq = self._seq[items[0][0].id]
        if imu:
            return cdr.decode_imu_rates_ros1(raws, header_seq=seq)
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
    """Say when the calibrated-range guard limited or extrapolated the correction of a run."""
    notes = []
    total = max(counters.imu_total, 1)
    model = coeffs.model
    t_rng, r_rng = model.temperature_range_degC, model.tdot_range_degC_per_min
    for count, text in (
        (
            counters.imu_temperature_clamped,
            f'temperature left the calibrated range [{t_rng.low:.3g}, {t_rng.high:.3g}] degC '
            'and was clamped',
        ),
        (
            counters.imu_tdot_clamped,
            'Tdot was clamped (to the calibrated range with --clamp-tdot, else to '
            'tdot_limit_degC_per_min)',
        ),
        (
            counters.imu_tdot_extrapolated,
            f'Tdot left the calibrated range [{r_rng.low:.3g}, {r_rng.high:.3g}] degC/min; the '
            'linear Tdot terms were applied beyond it',
        ),
    ):
        if count:
            notes.append(
                f'note: {name}: {text} for {100 * count / total:.0f} % of the gyro samples'
            )
    return notes
