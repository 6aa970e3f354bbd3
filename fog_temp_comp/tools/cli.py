"""``fog-temp-comp`` command line: ``main``, and parsed arguments dispatched to the commands.

The parser itself is :mod:`~fog_temp_comp.tools.cli_parser`; here the parsed arguments become
the options of :mod:`~fog_temp_comp.tools.commands` (and the fleet and demo commands), and user
errors, Ctrl-C and SIGTERM become one line on stderr and an exit code.

Start-up: only argparse and the plain name lists are imported at module level, so ``--help``
and argument errors cost no numpy, scipy, rosbags or matplotlib; a command imports what it
needs when it runs (``benchmarks/bench_startup.py``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from fog_temp_comp.tools.cli_parser import build_parser
from fog_temp_comp.tools.closed_pipe import ClosedPipeSafe

if TYPE_CHECKING:
    from fog_temp_comp.core.compensator import GuardSettings
    from fog_temp_comp.core.rest import RestSettings
    from fog_temp_comp.tools.commands import CalibrateOptions

__all__ = ['BLAS_THREADS', 'build_parser', 'calibrate_options', 'main', 'parse_calibrate', 'run']


def _terms(args: argparse.Namespace) -> tuple[str, ...] | None:
    """``--terms`` as a tuple; None (choose by cross-validation) only when nothing was asked."""
    if args.terms is not None:
        return tuple(t.strip() for t in args.terms.split(',') if t.strip())
    if args.denoise is not None:
        return ('const', 'T', 'Tdot')
    return None


def _guard(args: argparse.Namespace) -> GuardSettings:
    from fog_temp_comp.core.compensator import GuardSettings

    if args.extrapolate_tdot:
        print('note: --extrapolate-tdot is the default now; the flag is ignored', file=sys.stderr)
    return GuardSettings(clamp_tdot=args.clamp_tdot, adopt_delivery=not args.keep_timing)


def _rest(args: argparse.Namespace) -> RestSettings | None:
    from fog_temp_comp.core.rest import RestSettings

    if not args.rest_learning:
        return None
    names = (
        'window_s',
        'gyro_std_max_deg_h',
        'accel_std_max_m_s2',
        'accel_drift_max_m_s2',
        'residual_limit_deg_h',
        'time_constant_s',
    )
    fields = {name: getattr(args, 'rest_' + name) for name in names}
    return RestSettings(enabled=True, **fields)


def calibrate_options(args: argparse.Namespace) -> CalibrateOptions:
    """:class:`~fog_temp_comp.tools.commands.CalibrateOptions` of parsed calibrate arguments."""
    from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
    from fog_temp_comp.tools import commands

    guard = _guard(args)
    return commands.CalibrateOptions(
        gyro_topic=args.gyro_topic,
        temp_topic=args.temp_topic,
        temp_field=args.temp_field,
        temp_frame_id=args.temp_frame_id,
        gyro_frame_id=args.gyro_frame_id,
        time_source=args.time_source,
        settings=dataclasses.replace(RECOMMENDED_SETTINGS, method=args.denoise or 'kalman'),
        terms=_terms(args),
        fit_coil_lag=args.fit_coil_lag,
        online_tdot=args.online_tdot,
        hac_lag=args.hac_lag,
        latitude_deg=args.latitude_deg,
        axes_orientation=args.axes_orientation,
        no_constant=args.no_constant,
        heldout=tuple(args.heldout),
        leave_one_run_out=args.leave_one_run_out,
        tolerance=args.tolerance,
        quantized_likelihood=not args.gaussian_readings,
        validate=tuple(args.validate),
        report_dir=args.report,
        clamp_tdot=guard.clamp_tdot,
        adopt_delivery=guard.adopt_delivery,
        prior=args.prior,
        quiet=args.quiet,
        drop_unidentifiable=args.drop_unidentifiable,
        strict=args.strict,
    )


def parse_calibrate(argv: Sequence[str]) -> tuple[list[Path], CalibrateOptions]:
    """Bags and options of ``calibrate`` arguments (without ``-o``); ValueError on a bad one."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    calibrate = sub.choices['calibrate']

    def error(message: str) -> NoReturn:
        raise ValueError(message)

    calibrate.error = error
    args = calibrate.parse_args([*argv, '-o', 'unused.yaml'])
    return list(args.bags), calibrate_options(args)


def run(args: argparse.Namespace) -> int:
    """Dispatch parsed arguments to a command (imported here, not at start-up)."""
    from fog_temp_comp.tools import commands

    if args.command == 'simulate' and args.fleet is not None:
        from fog_temp_comp.tools.fleet_sim import simulate_fleet_command

        return simulate_fleet_command(
            args.out_dir,
            args.fleet,
            fmt=args.fmt,
            imu_hz=args.imu_hz,
            temp_hz=args.temp_hz,
            seed=args.seed,
            faulty_fraction=args.faulty_fraction,
        )
    if args.command == 'simulate':
        return commands.simulate_command(
            args.out_dir,
            fmt=args.fmt,
            imu_hz=args.imu_hz,
            temp_hz=args.temp_hz,
            seed=args.seed,
            realistic=args.realistic,
            runs=args.runs,
            vehicle={
                'turn_on_shift_deg_h': args.turn_on_shift_deg_h,
                'power_on_heating_degC': args.power_on_heating_degC,
                'motion_period_s': args.motion_period_s,
                'motion_fraction': args.motion_fraction,
                'motion_rate_deg_s': args.motion_rate_deg_s,
            },
        )
    if args.command == 'calibrate':
        return commands.calibrate_command(args.bags, args.output, options=calibrate_options(args))
    if args.command == 'fleet':
        from fog_temp_comp.tools import fleet

        return fleet.fleet_command(args, parse_calibrate=parse_calibrate)
    if args.command == 'compensate':
        return commands.compensate_command(
            args.in_bag,
            args.coeffs,
            args.output,
            gyro_topic=args.gyro_topic,
            temp_topic=args.temp_topic,
            temp_field=args.temp_field,
            temp_frame_id=args.temp_frame_id,
            output_topic=args.output_topic,
            denoise_method=args.denoise,
            guard=_guard(args),
            strict=args.strict,
            rest=_rest(args),
            rest_bias_in=args.rest_bias_in,
            rest_bias_out=args.rest_bias_out,
            time_source=args.time_source,
        )
    if args.command == 'evaluate':
        return commands.evaluate_command(
            args.bags,
            args.coeffs,
            gyro_topic=args.gyro_topic,
            temp_topic=args.temp_topic,
            temp_field=args.temp_field,
            temp_frame_id=args.temp_frame_id,
            gyro_frame_id=args.gyro_frame_id,
            denoise_method=args.denoise,
            guard=_guard(args),
            strict=args.strict,
            time_source=args.time_source,
        )
    from fog_temp_comp.tools.demo import demo_command

    return demo_command(bags_dir=args.bags, out_dir=args.out)


#: the command's matrices are thousands of rows by a few columns, where OpenBLAS's threads only
#: cost: with another process on the second core, calibrate ran 2x slower with 2 threads
#: (``benchmarks/bench_compensate.py``); a value set by the user is kept
BLAS_THREADS = {'OPENBLAS_NUM_THREADS': '1'}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fog-temp-comp`` console script."""
    for name, value in BLAS_THREADS.items():  # before numpy's first import
        os.environ.setdefault(name, value)
    try:  # Ctrl-C while the parser's imports run: nothing started, nothing written
        args = build_parser().parse_args(argv)
        from fog_temp_comp.tools.atomic import Terminated, terminating_on_signals
    except KeyboardInterrupt:
        print('interrupted: nothing written (during start-up)', file=sys.stderr)
        return 130

    stdout = sys.stdout
    sys.stdout = ClosedPipeSafe(stdout)  # ``| head``: the command still writes its outputs
    try:  # SIGTERM, SIGHUP: unwind (partial outputs removed) and exit 128 + n, as SIGINT
        with terminating_on_signals():
            from fog_temp_comp.tools import commands

            return _run_reporting_errors(args, commands.USER_ERRORS)
    except (KeyboardInterrupt, Terminated) as err:
        if not getattr(err, 'outputs_reported', False):
            outputs = [getattr(args, name, None) for name in ('output', 'report')]
            names = ', '.join(str(o) for o in outputs if o is not None)
            print(
                f'interrupted: nothing written{" to " + names if names else ""}', file=sys.stderr
            )
        return err.exit_code if isinstance(err, Terminated) else 130
    finally:
        sys.stdout = stdout


def _run_reporting_errors(
    args: argparse.Namespace, user_errors: tuple[type[BaseException], ...]
) -> int:
    """:func:`run`; a user error or an OS error becomes one ``ERROR:`` line and exit code 1."""
    try:
        return run(args)
    except user_errors as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except OSError as err:  # unwritable output, disk full, permissions
        where = f'{err.filename}: ' if err.filename else ''
        print(f'ERROR: {where}{err.strerror or err}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
