"""Which temperature sensor to calibrate on, where the bags carry several.

A unit may log more than one temperature: a sensor on the housing and one on the coil's hub,
one per coil, the electronics board's, each on a topic of its own or all on one topic told
apart by ``header.frame_id``. Which of them the drift follows best is a property of the unit
(where each sensor sits, its lag, its steps), not of their names. So ``calibrate`` runs its
default model choice (:func:`fog_temp_comp.core.model_choice.choose_and_calibrate`) on each
sensor's readings and keeps the sensor whose chosen pipeline has the best cross-validated
score: the same score, on the same gyro rows, that chose the model, so the sensors are judged
as the models are (held-out stability after / before, lower is better).

This module holds the comparison (:func:`choose_source`), the YAML's record of it
(:func:`sources_record`) and its text table (:func:`format_sources`); the bag reading is the
command's (:mod:`fog_temp_comp.tools.temperature_sources`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # (the offline commands import this module; only calibrate fits)
    from fog_temp_comp.core.calibration import CalibrationResult
    from fog_temp_comp.core.model_candidates import StructureScore

__all__ = [
    'SourceOutcome',
    'TemperatureSource',
    'choose_source',
    'format_sources',
    'sources_record',
]


@dataclass(frozen=True)
class TemperatureSource:
    """One temperature sensor in the bags: its topic and, on a shared topic, its frame_id."""

    topic: str
    #: of a topic that carries several sensors' readings, this one's ('' where it carries one)
    frame_id: str = ''

    @property
    def label(self) -> str:
        """``/fog/temperature`` or ``/fog/temperature [coil_x]``."""
        return self.topic + (f' [{self.frame_id}]' if self.frame_id else '')


@dataclass
class SourceOutcome:
    """The default model choice run on one sensor's readings, or why it could not run."""

    source: TemperatureSource
    result: CalibrationResult | None = None
    #: the structure chosen (its score with Gaussian readings, unless a rival won with the
    #: quantized filter)
    chosen: StructureScore | None = None
    error: str = ''

    @property
    def criterion(self) -> float:
        """The cross-validated score of the pipeline that runs (inf where it failed).

        The quantized-likelihood filter's score where the choice kept it
        (``provenance.selection.quantized_likelihood``), else the chosen structure's.
        """
        if self.chosen is None or self.error:
            return math.inf
        selection = self.result.coefficients.provenance.get('selection') if self.result else None
        quantized = (selection or {}).get('quantized_likelihood') or {}
        if quantized.get('used') and quantized.get('criterion') is not None:
            return float(quantized['criterion'])
        return float(self.chosen.criterion)


#: a sensor listed later replaces an earlier one only if it scores better by more than this
#: fraction (the model choice's :data:`~fog_temp_comp.core.model_choice.TOLERANCE`)
TOLERANCE = 0.02


def choose_source(
    outcomes: Sequence[SourceOutcome], tolerance: float = TOLERANCE
) -> SourceOutcome:
    """The first sensor, in the order given, within ``tolerance`` of the best score.

    As the model choice keeps the simplest structure within a tolerance of the best, this
    keeps the sensor listed first (the readers' default: the frame_id or topic that sorts
    first) unless another scores better by more than the fraction ``tolerance``: two sensors
    that read the coil alike do not trade places on the noise of their scores.

    Raises
    ------
    ValueError
        If no sensor could be calibrated on (each one's error in the message).

    """
    ok = [o for o in outcomes if math.isfinite(o.criterion)]
    if not ok:
        reasons = '; '.join(f'{o.source.label}: {o.error or "no score"}' for o in outcomes)
        raise ValueError(f'no temperature sensor could be calibrated on ({reasons})')
    best = min(o.criterion for o in ok)
    return next(o for o in ok if o.criterion <= best * (1.0 + tolerance))


def sources_record(outcomes: Sequence[SourceOutcome], chosen: SourceOutcome) -> dict[str, Any]:
    """The YAML's ``provenance.selection.temperature_sources``: each sensor's score, the choice."""
    return {
        'chosen': chosen.source.label,
        'sources': [
            {
                'topic': o.source.topic,
                **({'frame_id': o.source.frame_id} if o.source.frame_id else {}),
                'criterion': o.criterion if math.isfinite(o.criterion) else None,
                **({'structure': o.chosen.structure.name} if o.chosen is not None else {}),
                **({'error': o.error} if o.error else {}),
            }
            for o in outcomes
        ],
    }


def format_sources(outcomes: Sequence[SourceOutcome], chosen: SourceOutcome) -> str:
    """Plain-text table: each temperature sensor, its chosen model and score."""
    width = max(len('temperature sensor'), *(len(o.source.label) for o in outcomes))
    head = f'{"temperature sensor":<{width}} {"score":>7}  model chosen on it'
    lines = [head, '-' * len(head)]
    for o in outcomes:
        mark = '  <- used' if o is chosen else ''
        if o.error or o.chosen is None:
            lines.append(f'{o.source.label:<{width}} {"-":>7}  ERROR: {o.error}')
            continue
        lines.append(
            f'{o.source.label:<{width}} {o.criterion:>7.4f}  {o.chosen.structure.name}{mark}'
        )
    lines.append(
        '(each sensor gets the whole model choice; the first within the tolerance of the best '
        'score is used)'
    )
    return '\n'.join(lines)
