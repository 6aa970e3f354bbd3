"""What the model choice reports: the YAML's ``provenance.selection`` record and a text table.

Scores are the cross-validated ratios of bias stability after / before (lower is better).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from fog_temp_comp.core.model_candidates import StructureScore
from fog_temp_comp.core.sensor_noise import SensorNoise

__all__ = ['format_scores']


def _selection(
    scores: Sequence[StructureScore],
    chosen: StructureScore,
    mode: str,
    tolerance: float,
    noise: SensorNoise,
) -> dict[str, Any]:
    """The YAML's ``selection`` record: the choice, how it was scored, the best per model."""
    best_per_model: dict[str, StructureScore] = {}
    for s in scores:
        key = s.structure.model
        if key not in best_per_model or s.criterion < best_per_model[key].criterion:
            best_per_model[key] = s
    return {
        'chosen': chosen.structure.name,
        'mode': mode,
        'tolerance': tolerance,
        'criterion': 'geometric mean over held-out parts, axes and 10 s / 100 s of bias '
        'stability after / before (lower is better)',
        'sensor': {
            'temperature_quantum_degC': noise.quantum_degC,
            'temperature_noise_degC': noise.noise_degC,
        },
        'models': {
            key: {
                'best': s.structure.name,
                'criterion': s.criterion if math.isfinite(s.criterion) else None,
                'complexity': s.structure.complexity,
                **({'error': s.error} if s.error else {}),
            }
            for key, s in best_per_model.items()
        },
        'candidates': len(scores),
        'fit': chosen.structure.fit,
    }


def format_scores(scores: Sequence[StructureScore], chosen: StructureScore) -> str:
    """Plain-text table: the best settings of each model structure and its score."""
    best: dict[str, StructureScore] = {}
    for s in scores:
        if s.structure.model not in best or s.criterion < best[s.structure.model].criterion:
            best[s.structure.model] = s
    width = max([len('model'), *(len(key) for key in best)])
    head = f'{"model":<{width}} {"k":>2} {"best settings":<48} {"score":>7}'
    lines = [head, '-' * len(head)]
    for key, s in best.items():
        settings = s.structure.name[len(key) + 2 : -1]
        mark = ' <- chosen' if s.structure.model == chosen.structure.model else ''
        value = f'{s.criterion:>7.4f}' if math.isfinite(s.criterion) else f'ERROR: {s.error}'
        lines.append(f'{key:<{width}} {s.structure.complexity:>2} {settings:<48} {value}{mark}')
    lines.append(f'chosen: {chosen.structure.name}')
    lines.append(
        '(cross-validated score: geometric mean of held-out stability after/before at 10 s and '
        '100 s; k = fitted parameters per axis; the simplest within the tolerance wins, unless '
        'the line on a quantized sensor below names another)'
    )
    return '\n'.join(lines)
