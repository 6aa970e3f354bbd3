"""``fog-temp-comp calibrate``: fit drift coefficients on bags and write the YAML (and report).

:class:`CalibrateOptions` holds everything the command can be told; the fit is chosen by
cross-validation, held-out runs, a fleet prior or as asked (:func:`_fit`); optional
Earth-rate removal, validation replay and the HTML report (matplotlib, imported lazily).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from fog_temp_comp.bag.bag_path import short_names
from fog_temp_comp.bag.one_clock import on_one_clock
from fog_temp_comp.bag.reduce import reduce_record
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.bag.topic_names import default_output_topic
from fog_temp_comp.core.calibration import CalibrationResult, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients, load, save
from fog_temp_comp.core.compensator import GuardSettings
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.core.earth import earth_rate_body_deg_h, parse_orientation, remove_earth_rate
from fog_temp_comp.core.evaluate import format_scores, replay_record, score_record
from fog_temp_comp.core.fitstats import format_fits
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, coefficient_key
from fog_temp_comp.core.model_candidates import StructureScore
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.selection import default_candidates, format_results, select_and_calibrate
from fog_temp_comp.core.sensor_choice import TemperatureSource
from fog_temp_comp.tools.atomic import AtomicOutputs, check_output_directory
from fog_temp_comp.tools.evaluate_command import clamp_notes
from fog_temp_comp.tools.excitation import identifiable_terms
from fog_temp_comp.tools.salvaged import Salvaged
from fog_temp_comp.tools.temperature_sources import (
    Attempt,
    SeveralSensorsError,
    fit_on_best_source,
    several_sensors,
    source_read_args,
)


@dataclass(frozen=True)
class CalibrateOptions:
    """Everything ``fog-temp-comp calibrate`` can be told (units in the names)."""

    gyro_topic: str | None = None
    temp_topic: str | None = None
    temp_field: str | None = None
    #: of a temperature topic with several sensors' readings (frame_ids), this one's ('': choose)
    temp_frame_id: str = ''
    #: of a gyro topic with several gyros' messages (frame_ids), this one's ('': choose)
    gyro_frame_id: str = ''
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
    #: for a quantized sensor, fit its noise and use the exact likelihood of each reading
    #: (:func:`fog_temp_comp.core.model_choice.quantized_choice`); False: the Gaussian model
    quantized_likelihood: bool = True
    validate: tuple[Path, ...] = ()
    report_dir: Path | None = None
    clamp_tdot: bool = False
    #: take a driver's reading timing from the readings of --validate bags where it differs
    adopt_delivery: bool = True
    quiet: bool = True
    #: fit without the terms the bags do not excite (with a warning) instead of refusing
    drop_unidentifiable: bool = False
    #: refuse damaged bags instead of reading them as far as they are intact
    strict: bool = False
    #: a fleet prior YAML (``fleet prior``): fit toward it (:mod:`fog_temp_comp.core.prior`)
    prior: Path | None = None

    def guard(self) -> GuardSettings:
        """The input guards of the replays (``--validate``, ``--report``, held-out bags)."""
        return GuardSettings(clamp_tdot=self.clamp_tdot, adopt_delivery=self.adopt_delivery)


def calibrate_command(
    bags: Sequence[Path],
    output: Path,
    *,
    options: CalibrateOptions | None = None,
    settings: DenoiseSettings | None = None,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
) -> int:
    """Fit coefficients on ``bags`` and write them to ``output`` (YAML).

    Training bags are streamed and reduced to the Tdot grid (bounded memory); held-out and
    validation bags are replayed through the compensator at full rate. The fit's warnings go
    to ``stderr`` (default ``sys.stderr``).
    """
    stdout = stdout or sys.stdout
    check_output_directory(output)  # before the bags are read
    report = options.report_dir if options else None
    with AtomicOutputs(output, report) as outputs:  # -o, --report: complete, or not at all
        index = _calibrate(
            bags, output, outputs, options, settings, gyro_topic, temp_topic, (stdout, stderr)
        )
    print(f'wrote {output}', file=stdout)  # once in place, not before
    remap = node_remapping(output)
    if remap:
        print(remap, file=stdout)
    if index is not None:
        print(f'report: {index}', file=stdout)
    return 0


def _calibrate(
    bags: Sequence[Path],
    output: Path,
    outputs: AtomicOutputs,
    options: CalibrateOptions | None,
    settings: DenoiseSettings | None,
    gyro_topic: str | None,
    temp_topic: str | None,
    streams: tuple[TextIO, TextIO | None],
) -> Path | None:
    """:func:`calibrate_command` writing its outputs to the temporary paths of ``outputs``.

    Returns the report's index page (where it will be once committed), or None. ``streams``:
    stdout, and stderr for the fit's warnings (None: ``sys.stderr``).
    """
    stdout, stderr = streams
    yaml_path = outputs.path(output)  # first: an existing -o is refused before any bag is read
    opt = options or CalibrateOptions()
    report_dir = None
    if opt.report_dir is not None:  # a --report that cannot be written: before the fit, too
        report_dir = outputs.path(opt.report_dir, merge_into_dir=True)
    if opt.terms is not None and not opt.terms:
        raise ValueError('--terms: give at least one model term')
    opt = dataclasses.replace(
        opt,
        settings=settings or opt.settings,
        gyro_topic=gyro_topic or opt.gyro_topic,
        temp_topic=temp_topic or opt.temp_topic,
    )
    earth, provenance = _earth_correction(opt)
    if opt.prior is not None and (opt.terms or opt.fit_coil_lag or opt.heldout):
        raise ValueError('--prior sets the terms and Tdot settings; drop --terms/--fit-coil-lag')
    read = _read_args(opt)
    # of several temperature sensors in the bags, calibrate on each and keep the best
    choose = _automatic(opt) and opt.temp_field is None and not opt.temp_frame_id
    attempt = functools.partial(_attempt, opt, bags, read, earth, provenance, choose, stderr)
    attempted = fit_on_best_source(attempt, choose=choose, stdout=stdout)
    records, result = attempted.records, attempted.result
    opt, read = attempted.extra

    def load_record(bag: Path) -> ChamberRecord:
        """A validation bag's record (the sensor fitted) with the Earth rate removed."""
        return earth(on_one_clock(read_record, bag, **read))

    coeffs = result.coefficients
    if opt.no_constant:
        coeffs = _without_constant(coeffs)
    save(coeffs, yaml_path)
    _print_fit(result, coeffs, len(records), stdout, stderr or sys.stderr)
    named = [
        (n, load_record(b)) for n, b in zip(short_names(opt.validate), opt.validate, strict=True)
    ]
    runs = _validate(opt, coeffs, named, stdout)
    if opt.report_dir is None or report_dir is None:
        return None
    if not runs:  # no validation bags: show the training runs
        guard = opt.guard()
        for record in records:
            corrected, _ = replay_record(record, coeffs, guard=guard)
            runs.append((f'{record.path.name} (training)', record, corrected))
    index = _write_calibration_report(report_dir, bags, runs, result, coeffs, provenance)
    return opt.report_dir / index.name


#: the node's input topics (relative: remapped with ``-r``)
NODE_INPUTS = ('imu/data_raw', 'imu/temperature')
#: the node's output topic (relative)
NODE_OUTPUT = 'imu/data'


def node_remapping(coeffs_path: Path) -> str:
    """The ``ros2 run`` line for the fitted bags' topics, where they are not the node's; else ''.

    The output is remapped to the topic ``compensate`` writes (``/fog/rate_compensated`` for a
    gyro on ``/fog/rate``, ``/fog/data`` for ``/fog/data_raw``), so both paths agree. Read
    from the file's ``provenance`` (one gyro and one temperature topic: several bags on
    different topics give no single line).
    """
    provenance = load(coeffs_path).provenance
    gyro, temp = provenance.get('gyro_topics') or [], provenance.get('temperature_topics') or []
    if len(gyro) != 1 or len(temp) != 1:
        return ''
    pairs = [(n, t) for n, t in zip(NODE_INPUTS, (gyro[0], temp[0]), strict=True)]
    if all(t == f'/{n}' for n, t in pairs):
        return ''
    # the output on the topic compensate gives it (/fog/rate_compensated for /fog/rate)
    pairs.append((NODE_OUTPUT, default_output_topic(gyro[0])))
    remaps = ' '.join(f'-r {n}:={t}' for n, t in pairs if t != f'/{n}')
    return (
        "the bags' topics are not the node's inputs (imu/data_raw, imu/temperature); run it "
        f'with: ros2 run fog_temp_comp compensator --ros-args -p coefficients_file:='
        f'{coeffs_path.resolve()} {remaps}'
    )


def _read_args(opt: CalibrateOptions) -> dict[str, Any]:
    """The bag readers' keyword arguments that ``opt`` sets."""
    return dict(
        gyro_topic=opt.gyro_topic,
        temp_topic=opt.temp_topic,
        temp_field=opt.temp_field,
        temp_frame_id=opt.temp_frame_id,
        gyro_frame_id=opt.gyro_frame_id,
        time_source=opt.time_source,
        quiet=opt.quiet,
        strict=opt.strict,
    )


def _attempt(
    opt: CalibrateOptions,
    bags: Sequence[Path],
    read: dict[str, Any],
    earth: Callable[[ChamberRecord], ChamberRecord],
    provenance: dict[str, Any],
    choose: bool,
    err: TextIO | None,
    source: TemperatureSource | None,
    out: TextIO,
) -> Attempt:
    """Read the training (and held-out) bags with ``source``'s readings and fit.

    Prints to ``out``, its warnings to ``err`` (None: ``sys.stderr``); the attempt's ``extra``
    holds the options and reader arguments used.
    """
    salvaged = Salvaged(err)
    args = {**read, **source_read_args(source), 'on_salvage': salvaged.add}
    if choose and (source is None or source.frame_id):  # the table after the fits says which
        args['frame_notes'] = False  # sensor of a topic is kept (of topics: their notes)
    period = opt.settings.tdot_period_s
    # a chunk skipped inside a run splits it: the grid never bridges what was lost
    records = [
        earth(piece)
        for b in bags
        for piece in salvaged.split(on_one_clock(reduce_record, b, period, **args), period)
    ]
    if choose and source is None and several_sensors(records):
        raise SeveralSensorsError(records)  # each sensor's readings get an attempt of their own
    if opt.prior is None:  # with a fleet prior, the prior carries what a short run lacks
        drop = opt.drop_unidentifiable
        terms = identifiable_terms(records, opt.terms, drop=drop, stderr=err or sys.stderr)
        opt = dataclasses.replace(opt, terms=terms)
    # held-out bags as the training ones: non-finite samples dropped, split at pauses
    heldout = [
        earth(piece)
        for b in opt.heldout
        for piece in salvaged.split(on_one_clock(read_record, b, **args))
    ]
    result, chosen = _fit(opt, records, heldout, {**provenance, **salvaged.provenance()}, out)
    return Attempt(records, result, chosen, extra=(opt, args))


def _automatic(opt: CalibrateOptions) -> bool:
    """Whether calibrate chooses the model by cross-validation (no flag that sets it)."""
    return (
        opt.terms is None
        and not opt.fit_coil_lag
        and not opt.online_tdot
        and not opt.leave_one_run_out
        and opt.settings.method == 'kalman'
        and opt.prior is None
    )


def _fit(
    opt: CalibrateOptions,
    records: list[ChamberRecord],
    heldout: list[ChamberRecord],
    provenance: dict[str, Any],
    stdout: TextIO,
) -> tuple[CalibrationResult, StructureScore | None]:
    """The calibration result: chosen by cross-validation, by held-out runs, or as asked.

    With it the structure chosen by cross-validation and the score of what runs (else None).
    """
    if opt.prior is not None:
        from fog_temp_comp.core import prior

        result = prior.calibrate_with_prior(
            records, prior.load_prior(opt.prior), provenance=provenance
        )
        print(prior.format_prior_fit(result), file=stdout)
        return result, None
    if _automatic(opt):
        from fog_temp_comp.core import model_choice

        result, cv_scores, cv_chosen = model_choice.choose_and_calibrate(
            records,
            opt.settings,
            heldout=heldout,
            tolerance=opt.tolerance,
            hac_lag=opt.hac_lag,
            provenance=provenance,
            quantized_likelihood=opt.quantized_likelihood,
        )
        print(model_choice.format_scores(cv_scores, cv_chosen), file=stdout)
        quantized = (result.coefficients.provenance.get('selection') or {}).get(
            'quantized_likelihood'
        )
        if quantized:
            print(model_choice.format_quantized(quantized), file=stdout)
        return result, cv_chosen
    if opt.heldout or opt.leave_one_run_out:
        candidates = default_candidates(opt.settings)
        coeffs, chosen, results = select_and_calibrate(
            candidates,
            records,
            heldout or None,
            guard=opt.guard(),
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
        ), None
    return calibrate_detailed(
        records,
        opt.settings,
        terms=opt.terms or PAPER_TERMS,
        fit_coil_lag=opt.fit_coil_lag,
        online_tdot=opt.online_tdot,
        hac_lag=opt.hac_lag,
        provenance=provenance,
    ), None


def _print_fit(
    result: CalibrationResult, coeffs: Coefficients, n_bags: int, stdout: TextIO, stderr: TextIO
) -> None:
    """The fitted terms, each fit's statistics, the calibrated range; the warnings on stderr.

    The bags counted are those fitted on (a repeat of another left out), ``n_bags`` where the
    provenance does not name them.
    """
    model = coeffs.model
    lag, sensor_lag = coeffs.denoise.coil_lag_s, coeffs.denoise.sensor_lag_s
    fitted = coeffs.provenance.get('bags')
    n_bags = len(set(fitted)) if isinstance(fitted, list) and fitted else n_bags
    repeats = len(coeffs.provenance.get('repeated_bags') or ())
    print(
        f'fitted {", ".join(model.terms)} on {n_bags} bag(s)'
        + (f' ({repeats} left out, repeating another)' if repeats else '')
        + f', Tdot estimator '
        f'{coeffs.denoise.method}'
        + (f', coil lag {lag:.0f} s' if lag else '')
        + (f', sensor lag {sensor_lag:.0f} s' if sensor_lag else ''),
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
    timing = _reading_timing(coeffs.denoise)
    if timing:
        print(f'  temperature readings: {timing}', file=stdout)
    for warning in result.warnings:
        print(f'WARNING: {warning}', file=stderr)


def _reading_timing(denoise: DenoiseSettings) -> str:
    """How the driver delivers the readings, where not one by one as taken ('' if so)."""
    period = denoise.temperature_period_s
    if denoise.temperature_hold_s:
        return (
            f'published only on change (a conversion every {period:.3g} s): each value held for '
            f'up to {denoise.temperature_hold_s:g} s (denoise.temperature_hold_s)'
        )
    if denoise.temperature_spread_s:
        return (
            f'delivered in polls every {period:.3g} s, stamped on receipt: stamped back at the '
            f"sensor's {denoise.temperature_spread_s:g} s interval (denoise.temperature_spread_s)"
        )
    return ''


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
    guard = opt.guard()
    scores = []
    notes = []
    for name, record in named:
        corrected, status = replay_record(record, coeffs, guard=guard)
        scores += score_record(name, record.imu_stamps_s, record.rates_rad_s, corrected)
        notes += clamp_notes(name, status, coeffs)
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
