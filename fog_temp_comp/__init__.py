"""Real-time temperature-drift compensation for fibre-optic gyroscopes (FOG).

The package is cut in layers, each importing only those below it (``test/test_layers.py``):

- :mod:`fog_temp_comp.core`: the pure core (numpy/scipy): model, Tdot estimators, compensator,
  calibration, coefficients YAML; importable without ROS or a bag library;
- :mod:`fog_temp_comp.bag`: reading and writing bags (on ``core``);
- :mod:`fog_temp_comp.ros`: the ROS 2 node (on ``core``);
- :mod:`fog_temp_comp.tools`: the ``fog-temp-comp`` command line (on ``core`` and ``bag``).

The flat module names of version 0.1 (``fog_temp_comp.model``, ``fog_temp_comp.bagio``, ...)
still import, with a :class:`DeprecationWarning` naming the new place.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings
from typing import Any

__version__ = '0.1.0'

#: flat module name of version 0.1 -> its layer now
_MOVED = {
    **dict.fromkeys(
        [
            'units',
            'record',
            'model',
            'coil',
            'denoise',
            'grid',
            'tdot',
            'compensator',
            'coefficients',
            'fitstats',
            'calibration',
            'metrics',
            'evaluate',
            'selection',
            'model_choice',
            'earth',
        ],
        'core',
    ),
    **dict.fromkeys(
        ['cdr', 'mcapscan', 'sqlitescan', 'ros1scan', 'bagio', 'stream', 'reduce'], 'bag'
    ),
    **dict.fromkeys(['node', 'diagnostics'], 'ros'),
    **dict.fromkeys(['cli', 'commands', 'report', 'simulate', 'plants', 'demo'], 'tools'),
}
#: names that also moved to another module: old module -> {name: new module}
_MOVED_NAMES = {'bagio': {'read_record': 'fog_temp_comp.bag.stream'}}


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``fog_temp_comp.<old>`` as a forwarding alias of its new module, with a warning."""

    def find_spec(
        self, fullname: str, path: Any = None, target: Any = None
    ) -> importlib.machinery.ModuleSpec | None:
        parent, _, name = fullname.rpartition('.')
        if parent == __name__ and name in _MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        name = spec.name.rpartition('.')[2]
        target = f'{__name__}.{_MOVED[name]}.{name}'
        warnings.warn(
            f'{spec.name} is now {target}; the old name will be removed',
            DeprecationWarning,
            stacklevel=2,
        )
        module = importlib.import_module(target)
        extra = _MOVED_NAMES.get(name, {})
        alias = types.ModuleType(spec.name, module.__doc__)

        def forward(attr: str) -> Any:
            if attr in extra:
                return getattr(importlib.import_module(extra[attr]), attr)
            return getattr(module, attr)

        alias.__getattr__ = forward  # type: ignore[method-assign]
        return alias

    def exec_module(self, module: types.ModuleType) -> None:
        """Nothing to run: the alias forwards every attribute."""


if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.append(_MovedModuleFinder())
