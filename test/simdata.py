"""Simulation settings and bag helpers shared by the tests."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.testing import assert_allclose

from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagWriter,
    make_imu,
    make_temperature,
    write_chamber_bag,
)
from fog_temp_comp.core.calibration import CalibrationResult, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig

#: the paper's model with Table 1-like coefficients (deg/h), T over -40..60 degC
EXAMPLE_MODEL = DriftModel(
    PAPER_TERMS,
    np.array([[-12.5, 3.2, -0.85], [-8.7e-4, 2.4e-3, -1.6e-3], [0.93, -0.62, 0.45]]),
    Range(-40.0, 60.0),
    Range(-0.5, 0.5),
)


def example_coefficients(**fields: Any) -> Coefficients:
    """:data:`EXAMPLE_MODEL`, IIR Tdot, frame ``imu_link``; ``fields`` replace any of them."""
    defaults: dict[str, Any] = {
        'model': EXAMPLE_MODEL,
        'denoise': DenoiseSettings(method='iir'),
        'frame_id': 'imu_link',
        'fit': {axis: {'residual_std_deg_h': 0.02} for axis in 'xyz'},
        'provenance': {'created_utc': '2026-01-01T00:00:00Z', 'bags': ['chamber_run']},
    }
    return Coefficients(**{**defaults, **fields})


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

#: a 0.2 degC/min cycle over 0..40 degC with 30 min holds (about 8 h), gyro 0.5 Hz: the model
#: choice's training run
EIGHT_HOUR_CYCLE = SimulationConfig(
    imu_hz=0.5,
    temp_hz=1.0,
    low_degC=0.0,
    high_degC=40.0,
    start_degC=20.0,
    cycle_soak_s=1800.0,
    lag_s=400.0,
    arw_10s_deg_h=0.01,
)


def bag_path(directory: Path, name: str, fmt: str) -> Path:
    """Where a bag called ``name`` goes: ROS 1 bags are ``.bag`` files, ROS 2 bags directories."""
    return directory / (name + '.bag' if fmt == 'ros1' else name)


def write_run(path: Path, fmt: str, run: SimulatedRun, **kwargs: Any) -> Path:
    """Write ``run`` as a bag with :func:`write_chamber_bag`."""
    write_chamber_bag(
        path,
        fmt,
        imu_stamps_s=run.imu_stamps_s,
        rates_rad_s=run.rates_rad_s,
        temp_stamps_s=run.temp_stamps_s,
        temperature_degC=run.temperature_degC,
        **kwargs,
    )
    return path


#: log times (ns) written out of order, with ties: readers must sort them as rosbags does
UNSORTED_STAMPS_NS = (5, 3, 3, 9, 1, 7, 3)


def write_unsorted_imu_bag(path: Path, fmt: str, topic: str) -> Path:
    """A bag of Imu messages written in the order of :data:`UNSORTED_STAMPS_NS`."""
    with BagWriter(path, fmt) as writer:
        writer.add_topic(topic, IMU_TYPE)
        for k, ns in enumerate(UNSORTED_STAMPS_NS):
            writer.write(topic, ns, make_imu(ns, f'f{k}', [k, 0, 0]))
    return path


#: a message to write: (log time ns, rank among equal log times, topic, message)
Event = tuple[int, int, str, Any]
#: the chamber topics, registered temperature first (readers break log-time ties by it)
CHAMBER_TOPICS = {'/imu/temperature': TEMPERATURE_TYPE, '/imu/data_raw': IMU_TYPE}


def temperature_events(
    run: SimulatedRun, frame_id: str = 'imu_link', log: Callable[[float], int] | None = None
) -> list[Event]:
    """``run``'s readings on ``/imu/temperature``, logged at their stamps (or ``log(stamp_s)``)."""
    events = []
    for t, value in zip(run.temp_stamps_s, run.temperature_degC, strict=True):
        ns = round(t * 1e9)
        events.append(
            (
                ns if log is None else log(t),
                0,
                '/imu/temperature',
                make_temperature(ns, frame_id, value),
            )
        )
    return events


def gyro_events(
    run: SimulatedRun, rank: int = 0, log: Callable[[float], int] | None = None
) -> list[Event]:
    """``run``'s gyro samples on ``/imu/data_raw`` (frame ``imu_link``).

    Ranked ``rank`` among messages of one log time, logged at their stamps (or ``log(stamp_s)``).
    """
    return [
        (
            round(t * 1e9) if log is None else log(t),
            rank,
            '/imu/data_raw',
            make_imu(round(t * 1e9), 'imu_link', w),
        )
        for t, w in zip(run.imu_stamps_s, run.rates_rad_s, strict=True)
    ]


def write_events(
    path: Path, fmt: str, events: Sequence[Event], topics: dict[str, str] = CHAMBER_TOPICS
) -> Path:
    """A bag of ``events`` in (log time, rank) order; ``topics`` ({name: type}) added first."""
    with BagWriter(path, fmt) as writer:
        for topic, msgtype in topics.items():
            writer.add_topic(topic, msgtype)
        for ns, _, topic, msg in sorted(events, key=lambda e: (e[0], e[1])):
            writer.write(topic, ns, msg)
    return path


def fits_as_clean(clean: SimulatedRun, hit: ChamberRecord) -> CalibrationResult:
    """The paper-terms fit of ``hit`` (``clean`` with bad readings), asserted to be ``clean``'s.

    Coefficients within 1 % (or 1e-3 deg/h per unit) of those fitted on the clean run.
    """
    reference = calibrate_detailed([clean.as_record()], RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    fitted = calibrate_detailed([hit], RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    assert_allclose(
        fitted.coefficients.model.coefficients,
        reference.coefficients.model.coefficients,
        rtol=0.01,
        atol=1e-3,
    )
    return fitted
