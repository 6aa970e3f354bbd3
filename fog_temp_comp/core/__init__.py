"""The pure core: drift model, Tdot estimation, compensation, calibration and their statistics.

Plain numpy, scipy, PyWavelets and PyYAML; no ROS, no bag library.

- units and data: ``units``, ``names``, ``record`` (a run as arrays), ``grid`` (10 s means),
  ``stamp_offset`` (time sources; two clocks);
- the drift model: ``model`` (terms), ``coefficients`` (the YAML), ``earth``;
- Tdot estimation: ``tdot`` (``make_estimator``) on ``tdot_estimate`` (the interface),
  ``tdot_kalman``, ``tdot_grid`` and ``tdot_following`` (coil lag, shrinkage, ``Tdot_lag``),
  ``coil``; the paper's denoisers: ``denoise`` on ``denoise_settings``, ``denoise_options``,
  ``wavelet_denoising`` and ``butterworth``;
- compensation: ``compensator`` (the object the node and ``compensate`` both run), with
  ``compensator_types`` (guards, counters, status) and ``compensator_arrays`` (block path),
  ``rest`` and ``restfile`` (bias learning at rest);
- calibration: ``calibration``, ``fitstats``, ``gls``, ``identifiability``, ``prior``;
  the default model choice ``model_choice`` on ``sensor_noise``, ``model_candidates``,
  ``cv_folds``, ``cross_validation`` and ``model_choice_record``; ``selection``;
- judging: ``evaluate`` and ``metrics``.

May import: the standard library, numpy, scipy, pywt, yaml, and ``fog_temp_comp.core`` only.
"""
