"""The ``fog-temp-comp`` argument parser: its sub-commands and their options (argparse only).

:func:`build_parser` builds the simulate / calibrate / compensate / evaluate / demo / fleet
parser; units are in the option names and help texts (Hz, degC, degC/min, deg/h, s). Only
argparse and the plain name lists are imported at module level, so ``--help`` and argument
errors cost no numpy, scipy, rosbags or matplotlib.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from fog_temp_comp import __version__
from fog_temp_comp.bag.names import FORMATS
from fog_temp_comp.core.names import METHODS, TDOT_LIMIT_DEGC_PER_MIN, TERM_NAMES
from fog_temp_comp.core.stamp_offset import TIME_SOURCES
from fog_temp_comp.tools.simulate_limits import (
    CYCLE_RANGE_DEGC_PER_MIN,
    MAX_MESSAGES_PER_RUN,
    MAX_RATE_HZ,
    SOAK_RANGE_DEGC,
)

__all__ = ['build_parser']


def _add_topics(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--gyro-topic',
        metavar='T',
        help="sensor_msgs/Imu topic (default: the bag's only Imu topic)",
    )
    parser.add_argument(
        '--temp-topic',
        metavar='T',
        help="sensor_msgs/Temperature topic, or with --temp-field any type's (default: the "
        "bag's only Temperature topic, else a bare std_msgs Float32/Float64 one named as a "
        'temperature)',
    )


def _add_strict(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        '--strict',
        action='store_true',
        help='refuse a damaged bag (cut, no footer or metadata, damaged chunk) instead of '
        'reading it as far as it is intact with a warning',
    )


def _add_guard(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        '--clamp-tdot',
        action='store_true',
        help='clamp Tdot to the calibrated range (default: the linear Tdot terms are applied '
        f'beyond it, up to +-{TDOT_LIMIT_DEGC_PER_MIN:g} degC/min, as in the '
        "paper's protocol: fit on one cycle rate, judge on faster ones)",
    )
    parser.add_argument(
        '--keep-timing',
        action='store_true',
        help="keep the coefficients' reading timing (denoise.temperature_*) even where the "
        'readings look published only on change or delivered in polls and it says neither '
        '(default: take their timing from them, as the node does)',
    )
    parser.add_argument(
        '--extrapolate-tdot',
        action='store_true',
        help='(deprecated: now the default) apply the Tdot terms beyond the calibrated range',
    )


def _add_rest(parser: argparse.ArgumentParser) -> None:
    from fog_temp_comp.core.rest import RestSettings

    defaults = RestSettings()
    g = parser.add_argument_group(
        "bias learning at rest (the node's rest_* parameters; rest from the Imu alone)"
    )
    g.add_argument(
        '--rest-learning',
        action='store_true',
        help='learn the residual constant bias per axis while at rest (off by default)',
    )
    for name, unit in (
        ('window_s', 'rest detection window (s)'),
        ('gyro_std_max_deg_h', 'largest gyro std in a rest window (deg/h)'),
        ('accel_std_max_m_s2', 'largest accelerometer std in a rest window (m/s^2)'),
        ('accel_drift_max_m_s2', 'largest accelerometer mean change within a window (m/s^2)'),
        ('residual_limit_deg_h', 'a residual above this is reported, not applied (deg/h)'),
        ('time_constant_s', 'lag of the applied residual (s)'),
    ):
        g.add_argument(
            '--rest-' + name.replace('_', '-'),
            dest='rest_' + name,
            type=float,
            default=getattr(defaults, name),
            metavar='X',
            help=f'{unit}; default %(default)s',
        )
    g.add_argument(
        '--rest-bias-in',
        type=Path,
        metavar='LEARNED.yaml',
        help="start from this learned bias (the node's rest_bias_file; refused if learned "
        'with other coefficients)',
    )
    g.add_argument(
        '--rest-bias-out',
        type=Path,
        metavar='LEARNED.yaml',
        help='write the bias learned in this replay (for the node or the next replay)',
    )


def _add_denoise(
    parser: argparse.ArgumentParser,
    default: str | None,
    default_text: str = 'as stored in the coefficients file',
) -> None:
    parser.add_argument(
        '--denoise',
        choices=METHODS,
        default=default,
        help='Tdot estimator: kalman (Kalman filter on T, Tdot), wavelet (the paper), iir '
        '(Butterworth), llr (local linear regression) or none'
        + f' (default: {default or default_text})',
    )


def _add_fleet(sub: Any) -> None:
    p = sub.add_parser('fleet', help='calibrate many gyros in parallel (Dask); the fleet prior')
    fleet = p.add_subparsers(dest='fleet_command', required=True, metavar='FLEET_COMMAND')
    f = fleet.add_parser('calibrate', help='calibrate every unit of a manifest, one task each')
    f.add_argument('manifest', type=Path, metavar='MANIFEST', help='YAML or CSV: unit -> bag(s)')
    f.add_argument(
        '-o',
        '--output',
        type=Path,
        required=True,
        metavar='OUT_DIR',
        help="folder of the units' coefficients, logs, fleet table and report (resumable)",
    )
    f.add_argument(
        '--scheduler',
        metavar='ADDR',
        help='a running Dask scheduler, tcp://HOST:PORT (default: an embedded LocalCluster)',
    )
    f.add_argument(
        '--workers', type=int, metavar='N', help='LocalCluster workers (default: CPU count)'
    )
    f.add_argument('--no-report', action='store_true', help='no OUT_DIR/report/index.html')
    f = fleet.add_parser('prior', help="the fleet's coefficient distribution as a prior")
    f.add_argument('fleet_dir', type=Path, metavar='OUT_DIR', help='a `fleet calibrate` output')
    f.add_argument(
        '-o',
        '--output',
        type=Path,
        required=True,
        metavar='PRIOR.yaml',
        help='the prior to write, for `calibrate --prior` (never overwritten)',
    )


def build_parser() -> argparse.ArgumentParser:
    """Argument parser with the simulate / calibrate / compensate / evaluate / demo commands."""
    parser = argparse.ArgumentParser(
        prog='fog-temp-comp',
        description='Temperature-drift calibration and compensation for fibre-optic gyros.',
    )
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for add in (
        _add_simulate,
        _add_calibrate,
        _add_compensate,
        _add_evaluate,
        _add_demo,
        _add_fleet,
    ):
        add(sub)
    return parser


def _add_simulate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``simulate`` command."""
    p = sub.add_parser('simulate', help='write synthetic thermal-chamber runs as bags')
    p.add_argument(
        'out_dir',
        type=Path,
        metavar='OUT_DIR',
        help='folder for the bags, their <run>.truth.npz and manifest.yaml (created; runs '
        'added to a folder of the same simulation join its manifest; files are never '
        'overwritten)',
    )
    p.add_argument(
        '--format', choices=FORMATS, default='mcap', dest='fmt', help='bag format (default mcap)'
    )
    p.add_argument(
        '--imu-hz',
        type=float,
        default=10.0,
        help=f'gyro rate (Hz, default 10; at most {MAX_RATE_HZ:,.0f})',
    )
    p.add_argument(
        '--temp-hz',
        type=float,
        default=1.0,
        help=f'temperature rate (Hz, default 1; at most {MAX_RATE_HZ:,.0f})',
    )
    p.add_argument(
        '--seed', type=int, default=0, help="random seed of the runs' noise (>= 0, default 0)"
    )
    p.add_argument(
        '--realistic',
        action='store_true',
        help="the accuracy study's chamber: sensor-to-coil lag, controller "
        'overshoot, T^2 nonlinearity, wandering bias',
    )
    p.add_argument(
        '--fleet',
        type=int,
        metavar='N',
        help='write N units drawn from a population (some faulty), one realistic 1 degC/min '
        'cycle each, and OUT_DIR/fleet.yaml, the manifest of `fleet calibrate`',
    )
    p.add_argument(
        '--faulty-fraction',
        type=float,
        default=0.1,
        metavar='F',
        help='with --fleet: fraction of faulty units (missing, damaged or short bags, a bad '
        'coil; default 0.1)',
    )
    p.add_argument(
        '--runs',
        type=_runs,
        metavar='KIND:SETPOINT,...',
        help="runs to write instead of the paper's plan, e.g. soak:20,cycle:1.0 (soak setpoint "
        f'in degC, {SOAK_RANGE_DEGC[0]:g}..{SOAK_RANGE_DEGC[1]:g}; cycle rate in degC/min, '
        f'{CYCLE_RANGE_DEGC_PER_MIN[0]:g}..{CYCLE_RANGE_DEGC_PER_MIN[1]:g}; each once; at most '
        f'{MAX_MESSAGES_PER_RUN:,} messages a run, gyro and temperature)',
    )
    _add_simulate_vehicle(
        p.add_argument_group(
            'vehicle (to judge bias learning at rest; the truth files hold the shift and rotation)'
        )
    )


def _add_simulate_vehicle(g: argparse._ArgumentGroup) -> None:
    """``simulate``'s vehicle options: turn-on shift, power-on heating, rest/motion phases."""
    g.add_argument(
        '--turn-on-shift-deg-h',
        type=_vector3,
        default=(0.0, 0.0, 0.0),
        metavar='X,Y,Z',
        help='constant bias of this power-on, not in the true coefficients (deg/h per axis; '
        'default 0,0,0)',
    )
    g.add_argument(
        '--power-on-heating-degC',
        type=float,
        default=0.0,
        metavar='DT',
        dest='power_on_heating_degC',
        help="every run starts at power-on and the unit's own dissipation warms its housing "
        'DT degC above the chamber air (default 0: the unit on and settled before each run)',
    )
    g.add_argument(
        '--motion-period-s',
        type=float,
        default=0.0,
        metavar='S',
        help='rest/motion cycle: each period the unit rests, then moves (default 0: always at '
        'rest, a chamber)',
    )
    g.add_argument(
        '--motion-fraction',
        type=float,
        default=0.5,
        metavar='F',
        help='moving part of each period, the end of it (0..1; default 0.5)',
    )
    g.add_argument(
        '--motion-rate-deg-s',
        type=float,
        default=5.0,
        metavar='R',
        help='amplitude of the 0.5 Hz shaking rotation while moving, each axis (deg/s; default 5)',
    )


def _vector3(text: str) -> tuple[float, float, float]:
    """``'1,-2,0.5'`` -> three floats (argparse type)."""
    parts = text.split(',')
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f'expected X,Y,Z (three numbers), got {text!r}')
    return (values[0], values[1], values[2])


def _runs(text: str) -> list[tuple[str, float]]:
    """``'soak:20,cycle:1'`` -> [('soak', 20.0), ('cycle', 1.0)] (argparse type)."""
    runs = []
    for item in text.split(','):
        kind, _, setpoint = item.partition(':')
        try:
            value = float(setpoint)
        except ValueError:
            value = math.nan
        if kind not in ('soak', 'cycle') or not math.isfinite(value):
            raise argparse.ArgumentTypeError(
                f'expected soak:<degC> or cycle:<degC/min>, comma separated; got {item!r}'
            )
        runs.append((kind, value))
    return runs


def _add_calibrate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``calibrate`` command: bags, output, then its option groups."""
    p = sub.add_parser('calibrate', help='fit drift coefficients from chamber bags')
    p.add_argument(
        'bags',
        type=Path,
        nargs='+',
        metavar='BAG',
        help='chamber runs to fit together: rosbag2 folders, .mcap/.db3 files or ROS 1 .bag',
    )
    p.add_argument(
        '-o',
        '--output',
        type=Path,
        required=True,
        metavar='COEFFS.yaml',
        help='the coefficients file to write (never overwritten)',
    )
    _add_topics(p)
    _add_denoise(
        p,
        None,
        "chosen with the model from the data; given, the paper's terms "
        'are fitted with it unless --terms',
    )
    _add_calibrate_input(p.add_argument_group('input'))
    _add_calibrate_model(p.add_argument_group('model'))
    _add_calibrate_selection(p.add_argument_group('selection and validation (held-out runs)'))


def _add_temp_field(
    g: argparse._ArgumentGroup | argparse.ArgumentParser, calibrate: bool = False
) -> None:
    """``--temp-field`` (a field of a message of any type) and ``--temp-frame-id``.

    The default of ``--temp-frame-id`` is told as ``calibrate`` (or else the others) has it.
    """
    default = (
        'calibrate fits each and keeps the best, the first by name where a flag sets the model'
        if calibrate
        else 'the one calibrate kept, named in the coefficients file'
    )
    g.add_argument(
        '--temp-field',
        metavar='FIELD',
        help='read temperature (degC) from this field (a.b.c) of --temp-topic, '
        'a message of any type',
    )
    g.add_argument(
        '--temp-frame-id',
        metavar='ID',
        default='',
        help="of a temperature topic that carries several sensors' readings (told by "
        f"header.frame_id), use this sensor's (default: {default})",
    )


def _add_gyro_frame_id(
    g: argparse._ArgumentGroup | argparse.ArgumentParser, calibrate: bool = False
) -> None:
    """``--gyro-frame-id``: one gyro's messages of a topic that carries several."""
    default = 'the first by name' if calibrate else "the coefficients' frame_id"
    g.add_argument(
        '--gyro-frame-id',
        metavar='ID',
        default='',
        help="of a gyro topic that carries several gyros' messages (told by header.frame_id), "
        f"use this gyro's (default: {default})",
    )


def _add_calibrate_input(g: argparse._ArgumentGroup) -> None:
    """Input options of calibrate: temperature field, time source, Earth rate."""
    _add_temp_field(g, calibrate=True)
    _add_gyro_frame_id(g, calibrate=True)
    _add_time_source(g)
    g.add_argument('--quiet', action='store_true', help='no progress line on stderr')
    _add_strict(g)
    g.add_argument(
        '--latitude-deg',
        type=float,
        metavar='DEG',
        help='subtract the Earth-rate projection at this latitude before the fit',
    )
    g.add_argument(
        '--axes-orientation',
        metavar='SPEC',
        help='sensor axes in ENU for --latitude-deg: enu, ned, nwu, ..., a '
        'quaternion x,y,z,w or a row-major 3x3 matrix',
    )


def _add_calibrate_model(g: argparse._ArgumentGroup) -> None:
    """Model options of calibrate: terms, constant, coil lag, Tdot, standard errors."""
    g.add_argument(
        '--terms',
        default=None,
        metavar='LIST',
        help=f'model terms, comma separated, from {sorted(TERM_NAMES)} and hinges '
        'T_above_<degC> (max(T - degC, 0): a bias table in T). Default: calibrate '
        'chooses the terms, the sensor-to-coil lead-lag and the Kalman settings by '
        'cross-validation on the bags (any of --terms, --denoise, --fit-coil-lag, '
        '--online-tdot or --leave-one-run-out fits what is asked instead; --terms '
        "const,T,Tdot is the paper's model)",
    )
    g.add_argument(
        '--no-constant',
        action='store_true',
        help='write the model without D0 (ArduPilot style: the offset, Earth '
        'rate included, comes from a start-up calibration)',
    )
    g.add_argument(
        '--drop-unidentifiable',
        action='store_true',
        help='fit without the terms the bags together do not excite (Tdot over soaks only, '
        'T over one soak), with a warning; default: refuse, naming the term and each '
        "bag's T and Tdot span",
    )
    g.add_argument(
        '--fit-coil-lag',
        action='store_true',
        help='fit a first-order lag (s) between the temperature sensor and the coil',
    )
    g.add_argument(
        '--online-tdot',
        action='store_true',
        help='fit with the Tdot the node computes, also for wavelet/iir/none',
    )
    g.add_argument(
        '--prior',
        type=Path,
        metavar='PRIOR.yaml',
        help='fit toward a fleet prior (`fleet prior`): terms and Tdot settings from the prior, '
        'a Bayesian (ridge) fit whose prior weight is chosen on held-out time blocks',
    )
    g.add_argument(
        '--hac-lag',
        type=int,
        metavar='N',
        help='Newey-West lag of the standard errors (default: data-driven)',
    )


def _add_calibrate_selection(g: argparse._ArgumentGroup) -> None:
    """Selection, validation, report and guard options of calibrate."""
    g.add_argument(
        '--heldout',
        type=Path,
        nargs='+',
        default=[],
        metavar='BAG',
        help='choose model terms and coil lag by these held-out runs',
    )
    g.add_argument(
        '--leave-one-run-out',
        action='store_true',
        help='choose by leave-one-run-out over the training bags',
    )
    g.add_argument(
        '--tolerance',
        type=float,
        default=0.02,
        help='keep the simplest candidate within this fraction of the best score (0.02)',
    )
    g.add_argument(
        '--gaussian-readings',
        action='store_true',
        help='keep the Gaussian reading model for a quantized temperature sensor (default: fit '
        'its noise and use the exact likelihood of each quantized reading where '
        'cross-validation does not score it worse)',
    )
    g.add_argument(
        '--validate',
        type=Path,
        nargs='+',
        default=[],
        metavar='BAG',
        help='print the stability/range table for these held-out bags',
    )
    g.add_argument(
        '--report',
        type=Path,
        metavar='DIR',
        help='write PNG plots and an HTML page (index.html) to DIR',
    )
    _add_guard(g)


def _add_time_source(p: Any) -> None:
    """``--time-source``: header stamps (default) or receive times (drivers on two clocks)."""
    p.add_argument(
        '--time-source',
        choices=TIME_SOURCES,
        default='header',
        help='align gyro and temperature by header stamp (default) or receive time',
    )


def _add_coeffs(p: argparse.ArgumentParser) -> None:
    """``--coeffs``: the coefficients file of compensate and evaluate."""
    p.add_argument(
        '--coeffs',
        type=Path,
        required=True,
        metavar='COEFFS.yaml',
        help='the coefficients file `calibrate` wrote (as the node loads it)',
    )


def _add_compensate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``compensate`` command."""
    p = sub.add_parser('compensate', help='replay a bag through the compensator')
    p.add_argument('in_bag', type=Path, metavar='IN_BAG', help='the bag to correct (any format)')
    _add_coeffs(p)
    p.add_argument(
        '-o',
        '--output',
        type=Path,
        required=True,
        metavar='OUT_BAG',
        help='the bag to write: the input plus the corrected Imu (never overwritten)',
    )
    _add_topics(p)
    _add_temp_field(p)
    p.add_argument(
        '--output-topic',
        metavar='T',
        help='topic of the corrected Imu (default: NS/data for a gyro on NS/data_raw, so '
        '/imu/data for /imu/data_raw; else, or where the input has NS/data, the gyro topic + '
        '_compensated); a valid ROS topic name',
    )
    _add_time_source(p)
    _add_denoise(p, None)
    _add_guard(p)
    _add_strict(p)
    _add_rest(p)


def _add_evaluate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``evaluate`` command."""
    p = sub.add_parser('evaluate', help='bias stability and range before/after compensation')
    p.add_argument('bags', type=Path, nargs='+', metavar='BAG', help='runs to score, each apart')
    _add_coeffs(p)
    _add_topics(p)
    _add_temp_field(p)
    _add_gyro_frame_id(p)
    _add_time_source(p)
    _add_denoise(p, None)
    _add_guard(p)
    _add_strict(p)


def _add_demo(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``demo`` command."""
    p = sub.add_parser('demo', help="the paper's experiment on sample or simulated bags")
    p.add_argument(
        '--bags',
        type=Path,
        default=None,
        metavar='DIR',
        help='directory with manifest.yaml (default: simulate into OUT)',
    )
    p.add_argument(
        '--out',
        type=Path,
        default=Path('demo_out'),
        metavar='OUT',
        help='folder for the coefficients of each method and table.md (and bags/ when '
        'simulated; default demo_out)',
    )
