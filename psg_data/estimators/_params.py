"""Declared estimator settings: the project's one settings schema (:mod:`psg_data._settings`), whose
checks raise :class:`~psg_data.errors.EstimatorError` for estimators.
"""

from __future__ import annotations

from psg_data._settings import (
    Boolean,
    Integral,
    MappingParam,
    Options,
    Pair,
    Param,
    Real,
    Text,
    check_params,
    declared,
    parse_setting,
)

__all__ = ["Param", "Real", "Integral", "Options", "Boolean", "Pair", "MappingParam", "Text", "check_params",
           "parse_setting", "declared"]
