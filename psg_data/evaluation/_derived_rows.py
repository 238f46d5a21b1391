"""Rows scored from another row's predictions instead of running their own filters.

An estimator may declare that its predictions are a fixed map of another estimator's
(``derived_output()``: the other one's settings and the map). ``process_oracle:output=median`` is
the 0/1 median ``P >= 0.5`` of ``process_oracle``'s posterior: when a run has both rows with the
same seeds, the median row is not fitted or filtered again; each edge's beliefs of the
probability row are mapped and scored under the median row's name (one filter run per edge, the
same numbers: tested against running the row on its own). Only built-in estimators are trusted
with this declaration.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["DerivedRow", "derived_rows"]


@dataclass(frozen=True)
class DerivedRow:
    """A row scored as ``fn(predictions of base)``; ``params``: its own estimator's parameters."""

    base: str
    fn: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    params: dict[str, Any]


def _same(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    try:
        return a.keys() == b.keys() and all(bool(a[k] == b[k]) for k in a)
    except Exception:  # noqa: BLE001 - values without a plain equality (arrays): not the same row
        return False


def _built_in(name: str, settings: dict[str, Any]) -> Any:
    """The estimator ``name`` built with ``settings`` if it is a built-in class, else None."""
    from psg_data.estimators._registry import get_factory

    try:
        cls = get_factory(name)
        if not (isinstance(cls, type) and cls.__module__.startswith("psg_data.")):
            return None
        return cls(**settings)
    except Exception:  # noqa: BLE001 - a bad row is reported by its own fit, not here
        return None


def derived_rows(rows: Mapping[str, tuple[str, dict[str, Any]]], seeds: Mapping[str, tuple[int, ...]]
                 ) -> dict[str, DerivedRow]:
    """Row label -> :class:`DerivedRow` for each row that another row of the run derives.

    Args:
        rows: label -> (registry name, settings) of the run's registry rows.
        seeds: label -> the seeds each row is run with (a base must have the same).
    """
    out: dict[str, DerivedRow] = {}
    for label, (name, settings) in rows.items():
        est = _built_in(name, settings)
        spec = getattr(est, "derived_output", lambda: None)() if est is not None else None
        if spec is None:
            continue
        base_params, fn = spec
        for other, (oname, osettings) in rows.items():
            if other == label or other in out or oname != name or seeds.get(other) != seeds.get(label):
                continue
            base = _built_in(oname, osettings)
            if base is not None and getattr(base, "derived_output", lambda: None)() is None \
                    and _same(base.get_params(), base_params):
                out[label] = DerivedRow(other, fn, est.get_params())
                break
    return out
