"""The offline commands as plain functions returning an exit code (the CLI only parses).

A facade: each command lives in a module of its own, re-exported here for the CLI's dispatch
(imported when a command runs, never for ``--help``), the fleet tools, tests and benchmarks:

- :mod:`~fog_temp_comp.tools.simulate_command`: ``simulate`` (bags, truth, manifest);
- :mod:`~fog_temp_comp.tools.calibrate_command`: ``calibrate`` and :class:`CalibrateOptions`;
- :mod:`~fog_temp_comp.tools.compensate_command`: ``compensate`` (its chunk path in
  :mod:`~fog_temp_comp.tools.chunkreplay`, its MCAP block path in
  :mod:`~fog_temp_comp.tools.blockreplay`);
- :mod:`~fog_temp_comp.tools.evaluate_command`: ``evaluate`` and the guard's notes;
- :mod:`~fog_temp_comp.tools.salvaged`: what the readers recovered from damaged bags.
"""

from __future__ import annotations

from fog_temp_comp.bag.bagio import BagError
from fog_temp_comp.core.calibration import CalibrationError
from fog_temp_comp.core.coefficients import CoefficientsError
from fog_temp_comp.tools.calibrate_command import CalibrateOptions, calibrate_command
from fog_temp_comp.tools.chunkreplay import ChunkReplayer, chunked
from fog_temp_comp.tools.compensate_command import ReplayError, compensate_command, remove_bag
from fog_temp_comp.tools.evaluate_command import clamp_notes, effective_settings, evaluate_command
from fog_temp_comp.tools.salvaged import Salvaged
from fog_temp_comp.tools.simulate_command import bag_name, simulate_command

__all__ = [
    'USER_ERRORS',
    'CalibrateOptions',
    'ChunkReplayer',
    'ReplayError',
    'Salvaged',
    'bag_name',
    'calibrate_command',
    'chunked',
    'clamp_notes',
    'compensate_command',
    'effective_settings',
    'evaluate_command',
    'remove_bag',
    'simulate_command',
]

#: errors that end a command with one ``ERROR:`` line and exit code 1
USER_ERRORS = (BagError, CalibrationError, CoefficientsError, FileExistsError, ValueError)
