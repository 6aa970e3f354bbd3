"""The offline tools: the ``fog-temp-comp`` command line and what only it needs.

``cli`` (argument parsing), ``commands`` (simulate, calibrate, compensate, evaluate), ``report``
(HTML and plots, matplotlib), ``simulate`` and ``plants`` (synthetic chamber runs and random
plants) and ``demo``.

May import: ``fog_temp_comp.core``, ``fog_temp_comp.bag`` and ``fog_temp_comp.tools``.
"""
