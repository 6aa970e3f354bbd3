"""Names and defaults the command line shows: plain Python, so ``--help`` imports nothing heavy.

The modules that implement them import them from here (one source of truth).
"""

#: Tdot estimators (:class:`~fog_temp_comp.core.denoise.DenoiseSettings` ``method``)
METHODS: tuple[str, ...] = ('wavelet', 'iir', 'none', 'llr', 'kalman')
#: methods that denoise the raw Tdot of the grid (the others work on temperature samples)
GRID_METHODS: tuple[str, ...] = ('wavelet', 'iir', 'none')
#: drift model terms (:data:`fog_temp_comp.core.model.TERMS`), in their order there
TERM_NAMES: tuple[str, ...] = ('const', 'T', 'Tdot', 'T2', 'T3', 'T_Tdot', 'Tdot_lag')
#: default bound on the Tdot fed to the model beyond the calibrated range, degC/min
TDOT_LIMIT_DEGC_PER_MIN = 5.0
