"""Reference copies of ``ForwardBelief._hour_kernel`` and ``weekday_pattern_marginals`` as of main df3898b
(issue 45), kept unchanged.

The package's kernel (psg_data/synth/_process.py) now adds the hold term to the jump term instead of
writing it into an empty array first, and the marginals compute each weekday's day matrix once;
tests/estimators/test_process_oracle_memo.py checks that both give the same bits. Do not edit except
to follow API renames.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.schemas._generator_model import EntityProcess, StepProcess, normalize_rows

__all__ = ["hour_kernel", "weekday_pattern_marginals"]


def hour_kernel(belief: Any, beta: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """``rho * routine + (1 - rho) * (hold + jumped * U)`` of ``belief`` (a ForwardBelief) into slot ``k``."""
    c = belief._slot(k)
    tot = beta.sum(axis=(1, 2))
    out = np.empty_like(beta)
    out[:, :, :-1] = beta[:, :, 1:]
    out[:, :, -1] = 0.0
    jumped = np.einsum("ps,pst->pt", beta[:, :, 0], belief.entity.jump)
    out += jumped[:, :, None] * belief.U
    out *= c.one_minus_rho
    flat = out.reshape(-1, out.shape[2])  # a view: (pattern, state) rows
    flat[c.rows] += c.rho * (tot[:, None] * c.u_routine)
    return out


def weekday_pattern_marginals(process: StepProcess, entity: EntityProcess, weeks: int = 30) -> NDArray[np.float64]:
    """(7, D) long-run P(pattern | weekday) of the day chain (unshifted calendar)."""
    D = entity.n_patterns
    acc = np.zeros((7, D))
    p = normalize_rows(entity.pattern_initial * entity.pattern_allowed[process.clock.weekday(0)])
    plain = StepProcess(process.timezone, process.start_date, process.days, process.step_hours,
                        {entity.entity_id: entity})
    for day in range(1, 7 * weeks):
        p = p @ plain.day_matrix(entity, day)
        if day >= 7 * (weeks - 8):
            acc[plain.clock.weekday(day)] += p
    return normalize_rows(acc)
