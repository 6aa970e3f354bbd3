"""calibrate's check that the bags excite each model term (refuse, or drop the term)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TextIO

from fog_temp_comp.core.calibration import CalibrationError
from fog_temp_comp.core.identifiability import record_span, unidentifiable_terms
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.record import ChamberRecord


def identifiable_terms(
    records: Sequence[ChamberRecord],
    terms: Sequence[str] | None,
    *,
    drop: bool,
    stderr: TextIO,
) -> tuple[str, ...] | None:
    """The terms to fit: ``terms`` unchanged when the records excite them all.

    ``terms`` None (calibrate chooses) is checked as the paper's model, the base of every
    candidate. A term the records together do not excite raises :class:`CalibrationError`
    naming it and each bag's T and Tdot span, or, with ``drop``, is left out with a
    ``WARNING:`` line (and the remaining terms are fitted as given).
    """
    spans = [record_span(r.path.name, r.temp_stamps_s, r.temperature_degC) for r in records]
    wanted = tuple(terms) if terms is not None else PAPER_TERMS
    problems = unidentifiable_terms(spans, wanted)
    if not problems:
        return None if terms is None else tuple(terms)
    if not drop:
        raise CalibrationError(
            problems[0].message + ' (or --drop-unidentifiable to fit without it)'
        )
    dropped = {p.term for p in problems}
    for problem in problems:
        print(
            f'WARNING: term {problem.term} dropped (--drop-unidentifiable): {problem.reason}',
            file=stderr,
        )
    return tuple(t for t in wanted if t not in dropped)
