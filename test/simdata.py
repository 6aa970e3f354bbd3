"""Simulation settings shared by the tests."""

from fog_temp_comp.simulate import SimulationConfig

#: a short chamber: 10..30 degC cycles with 10 min soaks, 1 Hz gyro and temperature
SHORT_CHAMBER = SimulationConfig(
    imu_hz=1.0,
    temp_hz=1.0,
    low_degC=10.0,
    high_degC=30.0,
    start_degC=20.0,
    cycle_soak_s=600.0,
    soak_duration_s=1800.0,
)
