"""The pure core: drift model, Tdot estimation, compensation, calibration and their statistics.

Plain numpy, scipy, PyWavelets and PyYAML; no ROS, no bag library. ``units``, ``record`` (a
run as arrays), ``model`` (drift terms), ``denoise``/``grid``/``coil``/``tdot`` (Tdot
estimators), ``compensator`` (the object the node and ``compensate`` both run),
``coefficients`` (the YAML), ``fitstats``/``calibration`` (least squares), ``model_choice``
(calibrate's default: the model chosen by cross-validation), ``selection``, ``evaluate``,
``metrics`` and ``earth``.

May import: the standard library, numpy, scipy, pywt, yaml, and ``fog_temp_comp.core`` only.
"""
