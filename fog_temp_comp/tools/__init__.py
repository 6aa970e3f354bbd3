"""The offline tools: the ``fog-temp-comp`` command line and what only it needs.

``cli`` (``main`` and dispatch) and ``cli_parser`` (argparse); ``commands`` (the
sub-commands, re-exported from ``simulate_command``, ``calibrate_command``,
``compensate_command`` and ``evaluate_command``), ``blockreplay`` and ``chunkreplay`` (compensate
a chunk at a time), ``salvaged`` (what damaged bags lost), ``atomic`` (outputs renamed into
place when complete); ``report`` (HTML and plots, matplotlib: ``report_allan``,
``report_plots``, ``report_html``); ``simulate`` and ``plants`` (synthetic chamber runs and
random plants), ``excitation``, ``demo``; ``fleet``, ``fleet_task``, ``fleet_manifest``,
``fleet_report`` and ``fleet_sim`` (many gyros on Dask).

May import: ``fog_temp_comp.core``, ``fog_temp_comp.bag`` and ``fog_temp_comp.tools``.
"""
