"""One fleet task: calibrate one unit on a worker, exactly as ``fog-temp-comp calibrate`` does.

Pure of Dask: the function runs on any worker (or inline) and returns a :class:`UnitResult`; the
client writes the files. Bad input (missing, damaged or too-short bags) is the unit's result,
``status='failed'`` with the reason; anything else raises, and Dask retries the task.
"""

from __future__ import annotations

import io
import tempfile
from dataclasses import dataclass
from pathlib import Path

from fog_temp_comp.tools import commands
from fog_temp_comp.tools.fleet_manifest import UnitJob, job_digest

#: longest reason kept in the fleet table
MAX_REASON_CHARS = 300


@dataclass(frozen=True)
class UnitResult:
    """The outcome of one unit: 'ok' (with the YAML text), 'failed' (with why) or 'skipped'."""

    unit: str
    status: str
    digest: str
    reason: str = ''
    yaml_text: str = ''
    log: str = ''


def calibrate_unit(job: UnitJob, previous_digest: str | None = None) -> UnitResult:
    """Calibrate ``job``, unless its content hash equals ``previous_digest`` ('skipped')."""
    digest = job_digest(job)
    if digest == previous_digest:
        return UnitResult(job.unit, 'skipped', digest)
    stdout = io.StringIO()
    with tempfile.TemporaryDirectory(prefix='fog-fleet-') as tmp:
        output = Path(tmp) / f'{job.unit}.yaml'
        try:
            commands.calibrate_command(
                job.bags, output, options=job.options, stdout=stdout, stderr=stdout
            )  # the warnings in the unit's log too
        except (*commands.USER_ERRORS, OSError) as err:
            reason = ' '.join(str(err).split())[:MAX_REASON_CHARS] or type(err).__name__
            log = stdout.getvalue() + f'ERROR: {err}\n'  # the log says why, in full
            return UnitResult(job.unit, 'failed', digest, reason=reason, log=log)
        text = output.read_text(encoding='utf-8')
        log = stdout.getvalue().replace(str(output), f'{job.unit}.yaml')
    return UnitResult(job.unit, 'ok', digest, yaml_text=text, log=log)
