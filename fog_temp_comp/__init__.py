"""Real-time temperature-drift compensation for fibre-optic gyroscopes (FOG).

The signal-processing core (this package minus :mod:`fog_temp_comp.node`) is plain numpy and
importable without ROS.
"""

__version__ = '0.1.0'
