"""The offline commands as plain functions returning an exit code (the CLI only parses)."""

from __future__ import annotations

import dataclasses
import shutil
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
import yaml

from fog_temp_comp.bag import bagio, cdr, mcapwrite
from fog_temp_comp.bag.bagio import BagError, BagWriter
from fog_temp_comp.bag.reduce import reduce_record
from fog_temp_comp.bag.repair import repaired_bag
from fog_temp_comp.bag.salvage import Salvage, finite_only, split_at_gaps
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.calibration import CalibrationError, CalibrationResult, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load, save
from fog_temp_comp.core.compensator import Compensator, CompensatorCounters, GuardSettings
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.core.earth import earth_rate_body_deg_h, parse_orientation, remove_earth_rate
from fog_temp_comp.core.evaluate import format_scores, replay_record, score_record
from fog_temp_comp.core.fitstats import format_fits
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, coefficient_key
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.rest import RestLearner, RestSettings
from fog_temp_comp.core.restfile import (
    check_learned_bias,
    file_sha256,
    learned_bias_from_status,
    read_learned_bias,
    write_learned_bias,
)
from fog_temp_comp.core.selection import default_candidates, format_results, select_and_calibrate
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools import blockreplay
from fog_temp_comp.tools.atomic import AtomicOutputs
from fog_temp_comp.tools.excitation import identifiable_terms

if TYPE_CHECKING:
    from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig

#: errors that end a command with one ``ERROR:`` line and exit code 1
USER_ERRORS = (BagError, CalibrationError, CoefficientsError, FileExistsError, ValueError)


class Salvaged:
    """What the readers recovered from damaged input bags: warns on stderr, feeds provenance."""

    def __init__(self, stderr: TextIO | None = None) -> None:
        self.stderr = stderr
        self.found: dict[Path, Salvage] = {}
        self.non_finite: dict[str, dict[str, int]] = {}  # bag -> samples dropped per stream
        self.disorder: dict[str, dict[str, dict[str, int]]] = {}  # bag -> stream -> counts

    def add(self, salvage: Salvage) -> None:
        """Called by the readers for a damaged bag (read as far as intact) or unsorted stamps."""
        order = salvage.order_summary()
        if order:
            self.disorder[str(salvage.path)] = {
                stream: {'out_of_order': late, 'duplicate': same}
                for stream, (late, same) in salvage.disorder.items()
            }
            print(f'WARNING: {order}', file=self.stderr or sys.stderr)
        if not salvage.recovered:
            return
        self.found[salvage.path] = salvage
        print(f'WARNING: {salvage.summary()}', file=self.stderr or sys.stderr)

    def split(self, record: ChamberRecord) -> list[ChamberRecord]:
        """``record`` without non-finite samples, cut at the chunks skipped inside it."""
        record, imu, temp = finite_only(record)
        if imu or temp:
            self.non_finite[str(record.path)] = {'gyro': imu, 'temperature': temp}
            print(
                f'WARNING: {record.path}: dropped {imu} gyro and {temp} temperature values '
                'that are not finite (NaN or inf)',
                file=self.stderr or sys.stderr,
            )
        return split_at_gaps(record, self.found.get(Path(record.path)))

    def provenance(self) -> dict[str, Any]:
        """Per recovered bag: what was wrong and what was lost; non-finite samples dropped."""
        out: dict[str, Any] = {}
        if self.found:
            out['recovered_inputs'] = [s.provenance() for s in self.found.values()]
        if self.non_finite:
            out['non_finite_dropped'] = dict(self.non_finite)
        if self.disorder:
            out['stamps_not_in_order'] = dict(self.disorder)
        return out


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
    deg/h, rest/motion phases); the truth files then hold ``turn_on_shift_deg_h`` and
    ``true_rotation_rad_s`` too (the oracle: rate minus drift, shift and rotation is noise).
    """
    # here, not at the top: the simulator needs scipy.signal (~1 s), no other command does
    from fog_temp_comp.tools.simulate import REALISTIC, SimulationConfig, paper_plan, simulate_run

    stdout = stdout or sys.stdout
    base = REALISTIC if realistic else SimulationConfig()
    cfg = config or dataclasses.replace(base, imu_hz=imu_hz, temp_hz=temp_hz, **(vehicle or {}))
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = _simulation_manifest(cfg, fmt, seed)
    with AtomicOutputs() as outputs:  # all files appear at the end, or none
        for k, (kind, setpoint) in enumerate(runs or paper_plan()):
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
    #: fit without the terms the bags do not excite (with a warning) instead of refusing
    drop_unidentifiable: bool = False
    #: refuse damaged bags instead of reading them as far as they are intact
    strict: bool = False
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
    report = options.report_dir if options else None
    with AtomicOutputs(output, report) as outputs:  # -o, --report: complete, or not at all
        return _calibrate(bags, output, outputs, options, settings, gyro_topic, temp_topic, stdout)


def _calibrate(
    bags: Sequence[Path],
    output: Path,
    outputs: AtomicOutputs,
    options: CalibrateOptions | None,
    settings: DenoiseSettings | None,
    gyro_topic: str | None,
    temp_topic: str | None,
    stdout: TextIO,
) -> int:
    """:func:`calibrate_command` writing its outputs to the temporary paths of ``outputs``."""
    opt = options or CalibrateOptions()
    if opt.terms is not None and not opt.terms:
        raise ValueError('--terms: give at least one model term')
    opt = dataclasses.replace(
        opt,
        settings=settings or opt.settings,
        gyro_topic=gyro_topic or opt.gyro_topic,
        temp_topic=temp_topic or opt.temp_topic,
    )
    earth, provenance = _earth_correction(opt)
    salvaged = Salvaged()
    read: dict[str, Any] = dict(
        gyro_topic=opt.gyro_topic,
        temp_topic=opt.temp_topic,
        temp_field=opt.temp_field,
        time_source=opt.time_source,
        quiet=opt.quiet,
        strict=opt.strict,
        on_salvage=salvaged.add,
    )

    def load_record(bag: Path) -> ChamberRecord:
        """A held-out or validation bag's record with the Earth rate removed."""
        return earth(read_record(bag, **read))

    period = opt.settings.tdot_period_s
    # a chunk skipped inside a run splits it: the grid never bridges what was lost
    records = [
        earth(piece) for b in bags for piece in salvaged.split(reduce_record(b, period, **read))
    ]
    if opt.prior is not None and (opt.terms or opt.fit_coil_lag or opt.heldout):
        raise ValueError('--prior sets the terms and Tdot settings; drop --terms/--fit-coil-lag')
    if opt.prior is None:  # with a fleet prior, the prior carries what a short run lacks
        terms = identifiable_terms(records, opt.terms, drop=opt.drop_unidentifiable, stdout=stdout)
        opt = dataclasses.replace(opt, terms=terms)
    heldout = [load_record(b) for b in opt.heldout]
    provenance = {**provenance, **salvaged.provenance()}
    result = _fit(opt, records, heldout, provenance, stdout)
    coeffs = result.coefficients
    if opt.no_constant:
        coeffs = _without_constant(coeffs)
    save(coeffs, outputs.path(output))
    _print_fit(result, coeffs, len(records), output, stdout)
    runs = _validate(opt, coeffs, [(b.name, load_record(b)) for b in opt.validate], stdout)
    if opt.report_dir is not None:
        if not runs:  # no validation bags: show the training runs
            guard = GuardSettings(clamp_tdot=opt.clamp_tdot)
            for record in records:
                corrected, _ = replay_record(record, coeffs, guard=guard)
                runs.append((f'{record.path.name} (training)', record, corrected))
        report_dir = outputs.path(opt.report_dir, merge_into_dir=True)
        index = _write_calibration_report(report_dir, bags, runs, result, coeffs, provenance)
        print(f'report: {opt.report_dir / index.name}', file=stdout)
    return 0


def _fit(
    opt: CalibrateOptions,
    records: list[ChamberRecord],
    heldout: list[ChamberRecord],
    provenance: dict[str, Any],
    stdout: TextIO,
) -> CalibrationResult:
    """The calibration result: chosen by cross-validation, by held-out runs, or as asked."""
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
        return result
    if automatic:
        from fog_temp_comp.core import model_choice

        result, cv_scores, cv_chosen = model_choice.choose_and_calibrate(
            records,
            opt.settings,
            heldout=heldout,
            tolerance=opt.tolerance,
            hac_lag=opt.hac_lag,
            provenance=provenance,
        )
        print(model_choice.format_scores(cv_scores, cv_chosen), file=stdout)
        return result
    if opt.heldout or opt.leave_one_run_out:
        candidates = default_candidates(opt.settings)
        coeffs, chosen, results = select_and_calibrate(
            candidates,
            records,
            heldout or None,
            guard=GuardSettings(clamp_tdot=opt.clamp_tdot),
            tolerance=opt.tolerance,
        )
        print(format_results(results, chosen), file=stdout)
        candidate = chosen.candidate
        return calibrate_detailed(
            records,
            coeffs.denoise,
            terms=candidate.terms,
            online_tdot=candidate.online_tdot,
            hac_lag=opt.hac_lag,
            provenance={**provenance, 'selection': coeffs.provenance.get('selection')},
        )
    return calibrate_detailed(
        records,
        opt.settings,
        terms=opt.terms or PAPER_TERMS,
        fit_coil_lag=opt.fit_coil_lag,
        online_tdot=opt.online_tdot,
        hac_lag=opt.hac_lag,
        provenance=provenance,
    )


def _print_fit(
    result: CalibrationResult, coeffs: Coefficients, n_bags: int, output: Path, stdout: TextIO
) -> None:
    """The fitted terms, each fit's statistics, the calibrated range and the warnings."""
    model = coeffs.model
    lag = coeffs.denoise.coil_lag_s
    print(
        f'fitted {", ".join(model.terms)} on {n_bags} bag(s), Tdot estimator '
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


def _validate(
    opt: CalibrateOptions,
    coeffs: Coefficients,
    named: list[tuple[str, ChamberRecord]],
    stdout: TextIO,
) -> list[tuple[str, ChamberRecord, Any]]:
    """Replay the validation records, print their table; (name, record, corrected) each."""
    runs: list[tuple[str, ChamberRecord, Any]] = []
    if not named:
        return runs
    guard = GuardSettings(clamp_tdot=opt.clamp_tdot)
    scores = []
    notes = []
    for name, record in named:
        corrected, status = replay_record(record, coeffs, guard=guard)
        scores += score_record(name, record.imu_stamps_s, record.rates_rad_s, corrected)
        notes += clamp_notes(name, status.counters, coeffs)
        runs.append((name, record, corrected))
    print('\nheld-out validation:', file=stdout)
    print(format_scores(scores), file=stdout)
    for note in notes:
        print(note, file=stdout)
    return runs


def _write_calibration_report(
    report_dir: Path,
    bags: Sequence[Path],
    runs: list[tuple[str, ChamberRecord, Any]],
    result: CalibrationResult,
    coeffs: Coefficients,
    provenance: dict[str, Any],
) -> Path:
    """The HTML report of a calibration (matplotlib imported only here); its index page."""
    from fog_temp_comp.tools.report import ReportRun, write_report

    scores = []
    report_runs = []
    for name, record, corrected in runs:
        scores += score_record(name, record.imu_stamps_s, record.rates_rad_s, corrected)
        report_runs.append(
            ReportRun(name, record.imu_stamps_s, record.rates_rad_s, corrected,
                      record.temp_stamps_s, record.temperature_degC)
        )  # fmt: skip
    return write_report(
        report_dir,
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
    strict: bool = False,
    rest: RestSettings | None = None,
    rest_bias_in: Path | None = None,
    rest_bias_out: Path | None = None,
    stdout: TextIO | None = None,
    fast: bool = True,
) -> int:
    """Replay ``in_bag`` through a :class:`Compensator`; write all inputs plus corrected Imu.

    Messages are processed in the bag's log-time order, i.e. the order a node sees on replay.
    ``fast`` (the default) reads an MCAP bag a chunk at a time and writes blocks
    (:mod:`~fog_temp_comp.tools.blockreplay`), other bags through ``AnyReader`` and
    :meth:`BagWriter.write_many`; ``fast=False`` writes through rosbags one message at a time.
    Both give the same bag. With ``rest`` (enabled) the bias learner at rest runs too, fed the
    Imu's accelerometer (through ``AnyReader``: the MCAP block path decodes rates only); it
    starts from the learned-bias file ``rest_bias_in`` (refused with an error if learned with
    other coefficients) and writes what it learned to ``rest_bias_out``
    (:mod:`~fog_temp_comp.core.restfile`, as the node's ``rest_bias_file``).
    """
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    if out_bag.exists():
        raise FileExistsError(f'{out_bag}: exists already, not overwriting')
    settings = effective_settings(coeffs, denoise_method)
    if (rest_bias_in or rest_bias_out) and not (rest is not None and rest.enabled):
        raise ValueError('--rest-bias-in/--rest-bias-out need --rest-learning')

    def new_compensator(out: TextIO | None = None) -> Compensator:
        compensator = Compensator(coeffs.model, settings, guard, rest)
        if rest_bias_in is not None:
            _start_rest_from(compensator, rest_bias_in, coeffs_path, out)
        return compensator

    new_compensator(stdout)  # refuse a learned-bias file that does not fit, before reading
    if output_topic and not output_topic.startswith('/'):
        output_topic = '/' + output_topic
    run = _Compensate(
        in_bag=in_bag,
        fmt=bagio.bag_format(in_bag),
        topics=(gyro_topic, temp_topic, output_topic),
        new_compensator=new_compensator,
        fast=fast,
    )
    (n_out, counters), compensator = _replay_atomically(run, in_bag, out_bag, strict)
    print(
        f'wrote {out_bag}: {n_out} corrected Imu on {output_topic} '
        f'({counters.imu_uncorrected} before the first temperature passed through)',
        file=stdout,
    )
    if compensator.rest is not None:
        _report_rest(compensator.rest, coeffs_path, rest_bias_out, stdout)
    return 0


def _replay_atomically(
    run: _Compensate, in_bag: Path, out_bag: Path, strict: bool
) -> tuple[tuple[int, CompensatorCounters], Compensator]:
    """``run`` into ``out_bag``, complete or not at all: (written, counters), the compensator.

    A bag whose damage shows only when read is repaired (what is intact copied) and replayed.
    """
    with AtomicOutputs(out_bag) as out:  # complete, or nothing at out_bag
        target = out.path(out_bag)
        try:
            with repaired_bag(in_bag, out_bag.parent, strict=strict) as (source, salvage):
                return run.into(target, source, salvage)
        except ReplayError as err:  # damage that shows only when read: copy what is intact
            remove_bag(target)
            with repaired_bag(in_bag, out_bag.parent, strict=strict, failure=err) as (
                source,
                salvage,
            ):
                return run.into(target, source, salvage)


def _report_rest(
    learner: RestLearner, coeffs_path: Path, rest_bias_out: Path | None, stdout: TextIO
) -> None:
    """Print what the bias learner at rest learned (deg/h); write it to ``rest_bias_out``."""
    st = learner.finish()
    print(
        f'rest learning: {st.windows_rest} rest windows learned from, '
        f'{st.windows_motion} moving, {st.windows_tilting} tilting, '
        f'{st.windows_over_limit} over the limit; learned '
        + ', '.join(f'{v:.3f}' for v in st.learned_deg_h)
        + ' deg/h (x, y, z), applied '
        + ', '.join(f'{v:.3f}' for v in st.applied_deg_h)
        + ' deg/h',
        file=stdout,
    )
    if rest_bias_out is None:
        return
    bias = learned_bias_from_status(
        st,
        learner.settings,
        coefficients_file=str(coeffs_path),
        coefficients_sha256=file_sha256(coeffs_path),
    )
    if bias is None:
        print(f'rest learning: nothing learned, {rest_bias_out} not written', file=stdout)
    else:
        write_learned_bias(rest_bias_out, bias)
        print(f'wrote {rest_bias_out} (learned bias)', file=stdout)


class ReplayError(BagError):
    """Reading the input failed while replaying it (a damaged bag: copied and tried again)."""


@dataclass
class _Compensate:
    """The settings of one ``compensate`` run, applied to a (possibly repaired) input."""

    in_bag: Path
    fmt: str
    topics: tuple[str | None, str | None, str]  # gyro, temperature, output
    new_compensator: Callable[[], Compensator]
    fast: bool

    def into(
        self, target: Path, source: Path, salvage: Salvage | None
    ) -> tuple[tuple[int, CompensatorCounters], Compensator]:
        """Write ``target`` from ``source``; (written, counters) and the compensator used.

        ``salvage`` (a repaired copy) is reported on stderr, and the spans it skipped inside
        the run restart the Tdot estimate (no correction bridged across a hole).
        """
        if salvage is not None:
            Salvaged().add(salvage)
        holes = [(a, b) for a, b in (salvage.gap_spans_s() if salvage else []) if b is not None]
        gyro_topic, temp_topic, output_topic = self.topics
        compensator = self.new_compensator()
        compensator.mark_holes(holes)
        opened = ExitStack()
        try:
            reader = opened.enter_context(bagio.open_bag(source))
        except BagError as err:
            if salvage is not None:
                raise
            raise ReplayError(str(err)) from err  # a stale metadata.yaml, ...: copy it
        with opened:
            job = _CompensateJob(
                reader=reader,
                in_bag=self.in_bag,
                out_bag=target,
                fmt=self.fmt,
                imu_name=bagio.resolve_topic(reader, gyro_topic, bagio.IMU_TYPE, '--gyro-topic'),
                temp_name=bagio.resolve_topic(
                    reader, temp_topic, bagio.TEMPERATURE_TYPE, '--temp-topic'
                ),
                output_topic=output_topic,
                compress=self.fmt == 'mcap' and _compressed_mcap(source),
            )
            if output_topic in reader.topics:
                raise BagError(
                    f'--output-topic {output_topic}: already in {self.in_bag}; choose another'
                )
            mcap = None
            block = self.fast and reader.is2 and compensator.rest is None
            if block and not blockreplay.per_message_compressed(reader):
                mcap = blockreplay.single_mcap_file(source)
            if mcap is not None:
                try:
                    result = job.run(compensator, mcap=mcap)
                    job.unstamped.warn(self.in_bag)
                    return result, compensator
                except (blockreplay.UnsupportedError, ValueError):
                    remove_bag(target)  # the per-message path decides (and words any error)
                    compensator = self.new_compensator()
                    compensator.mark_holes(holes)
                    job.unstamped = UnsetStamps()
            result = job.run(compensator, batched=self.fast)
            job.unstamped.warn(self.in_bag)
            return result, compensator


def _start_rest_from(
    compensator: Compensator, path: Path, coeffs_path: Path, out: TextIO | None
) -> None:
    """Start the bias learner from a learned-bias file; ValueError if it does not fit."""
    assert compensator.rest is not None
    bias = read_learned_bias(path)
    check_learned_bias(
        bias,
        coefficients_sha256=file_sha256(coeffs_path),
        earth_rate_body_deg_h=compensator.rest.settings.earth_rate_body_deg_h,
        path=path,
    )
    reason = compensator.rest.start_from(bias.bias_deg_h)
    if reason is not None:
        raise ValueError(f'{path}: {reason}')
    if out is not None:
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        print(f'rest learning: starting from {text} deg/h (x, y, z), {path}', file=out)


def _compressed_mcap(bag: Path) -> bool:
    """Whether an MCAP bag's (first file's first) chunk is compressed."""
    files = [bag] if bag.is_file() else sorted(bag.glob('*.mcap'))
    return bool(files) and mcapwrite.chunk_compression(files[0]) != ''


@dataclass
class _CompensateJob:
    """One ``compensate`` output: the input reader, the topics, where to write."""

    reader: Any
    in_bag: Path
    out_bag: Path
    fmt: str
    imu_name: str
    temp_name: str
    output_topic: str
    compress: bool = False
    #: unset header stamps (0) that took the receive time, per topic
    unstamped: UnsetStamps = dataclasses.field(default_factory=UnsetStamps)

    def run(
        self, compensator: Compensator, *, mcap: Path | None = None, batched: bool = True
    ) -> tuple[int, CompensatorCounters]:
        """Write the output bag; (corrected Imu written, the compensator's counters).

        With ``mcap``, :class:`blockreplay.UnsupportedError` and ``ValueError`` (damaged file)
        pass through for the caller to fall back; other errors become :class:`BagError`.
        The output is removed on any error.
        """
        try:
            with BagWriter(self.out_bag, self.fmt, compress=self.compress) as writer:
                self._add_topics(writer)
                if mcap is not None:
                    n_out = blockreplay.replay_mcap(
                        mcap,
                        writer,
                        compensator,
                        topics=set(self.reader.topics),
                        imu_topic=self.imu_name,
                        temp_topic=self.temp_name,
                        output_topic=self.output_topic,
                        unstamped=self.unstamped,
                    )
                else:
                    n_out = self._replay_messages(writer, compensator, batched)
        except Exception as err:
            remove_bag(self.out_bag)  # no half-written output
            if isinstance(err, BagError) or (
                mcap is not None and isinstance(err, (blockreplay.UnsupportedError, ValueError))
            ):
                raise
            raise ReplayError(
                f'{self.in_bag}: failed while replaying (damaged bag?): {err}'
            ) from err
        return n_out, compensator.status.counters

    def _add_topics(self, writer: BagWriter) -> None:
        reader = self.reader
        for conn in reader.connections:
            if conn.topic not in writer.topics:
                writer.add_topic(conn.topic, conn.msgtype, like=conn)
        imu_conn = next(c for c in reader.connections if c.topic == self.imu_name)
        # ROS 1: the corrected messages keep the input's layout (Header with seq)
        writer.add_topic(
            self.output_topic, bagio.IMU_TYPE, like=imu_conn if self.fmt == 'ros1' else None
        )

    def _replay_messages(self, writer: BagWriter, compensator: Compensator, batched: bool) -> int:
        """Through ``AnyReader``, a chunk at a time, written as a block or one by one."""
        messages = bagio.temperature_first(self.reader.messages(), self.temp_name)
        replayer = ChunkReplayer(
            compensator, self.reader, self.imu_name, self.temp_name, self.unstamped
        )
        n_out = 0
        for chunk in chunked(messages, 20_000):
            out = [(topic or self.output_topic, ns, raw) for topic, ns, raw in replayer.run(chunk)]
            n_out += len(out) - len(chunk)
            if batched:
                writer.write_many(out)
            else:
                for topic, log_ns, raw in out:
                    writer.write_raw(topic, log_ns, raw)
        return n_out


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

    def __init__(
        self,
        compensator: Compensator,
        reader: Any,
        imu_topic: str,
        temp_topic: str,
        unstamped: UnsetStamps | None = None,
    ):
        self.compensator = compensator
        #: unset header stamps (0) take the receive time; counted here
        self.unstamped = unstamped if unstamped is not None else UnsetStamps()
        self.ros2 = bool(reader.is2)
        self.imu_topic = imu_topic
        self.temp_topic = temp_topic
        #: the bias learner at rest wants the accelerometer: decode whole Imu messages
        self.with_accel = compensator.rest is not None
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
        rates = imu_batch.angular_velocity_rad_s if imu else np.empty((0, 3))
        accel = imu_batch.linear_acceleration if imu and self.with_accel else None
        # an unset temperature stamp takes the receive time (as the node takes its clock); an
        # unset gyro stamp goes to the compensator as it is (as on the node)
        imu_stamps = imu_batch.stamps_s if imu else np.empty(0)
        temp_logs = [chunk[k][1] for k in temp]
        temp_stamps = (
            self.unstamped.fill(self.temp_topic, temp_batch.stamps_s, temp_logs)
            if temp
            else np.empty(0)
        )
        temps = temp_batch.temperature_degC if temp else np.empty(0)
        # how many Imu (in chunk order) come before each temperature
        before = np.searchsorted(imu, temp) if imu else np.zeros(len(temp), dtype=np.int64)
        corrected, kept = self.compensator.correct_interleaved(
            imu_stamps, rates, temp_stamps, temps, before, accel
        )
        keep = np.flatnonzero(kept).tolist()
        patched = self._patch([chunk[imu[j]] for j in keep], corrected[kept].tolist())
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
            if imu and self.with_accel:
                return cdr.decode_imu_cdr(raws)
            return (cdr.decode_imu_rates_cdr if imu else cdr.decode_temperature_cdr)(raws)
        seq = self._seq[items[0][0].id]
        if imu and self.with_accel:
            return cdr.decode_imu_ros1(raws, header_seq=seq)
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
    strict: bool = False,
    stdout: TextIO | None = None,
) -> int:
    """Print stability and range before/after compensation for each bag and axis."""
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    scores = []
    notes = []
    salvaged = Salvaged()
    for bag in bags:
        record = read_record(
            bag,
            gyro_topic=gyro_topic,
            temp_topic=temp_topic,
            strict=strict,
            on_salvage=salvaged.add,
        )
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
