"""Declared estimator settings: types and ranges, checked before any work (scikit-learn's
``_parameter_constraints`` habit).

An estimator class lists its keyword-only settings once::

    class MyEstimator(BaseEstimator):
        _parameters = {
            "gamma": Real(0.0, 1.0, help="forgetting factor per observation"),
            "prior": Options("fremen", "none"),
            "max_components": Integral(1, 10),
            "p_m": Real(0.0, 0.5, closed="left", none_ok=True),
        }

:meth:`Param.check` validates a value (``set_params`` and :func:`check_params` use it) and
:meth:`Param.parse` turns command-line text (``psg-eval -e NAME:key=value``) into a value of the
declared type, so a bad setting fails in the command line before any data is read, with one line
naming the setting, the value and what is allowed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Integral as _IntegralNumber
from numbers import Real as _RealNumber
from typing import Any

from psg_data.errors import EstimatorError

__all__ = ["Param", "Real", "Integral", "Options", "Boolean", "Pair", "MappingParam", "Text", "check_params",
           "parse_setting"]

_NONE_WORDS = ("none", "null")
_TRUE_WORDS = ("true", "yes", "on", "1")
_FALSE_WORDS = ("false", "no", "off", "0")


@dataclass(frozen=True)
class Param:
    """One declared setting.

    Attributes:
        kind: "real", "int", "options", "bool", "pair" (two reals), "text" (a string, e.g. a path)
            or "mapping" (Python API only).
        low, high: bounds of "real" / "int" values (None: unbounded on that side).
        closed: which bounds are included: "both", "left", "right" or "neither".
        choices: allowed values of an "options" setting.
        none_ok: None is allowed (typically "estimate it from the data").
        help: one line for listings (units included).
    """

    kind: str
    low: float | None = None
    high: float | None = None
    closed: str = "both"
    choices: tuple[str, ...] = ()
    none_ok: bool = False
    help: str = ""

    def describe(self) -> str:
        """What is allowed, in words: ``a number in [0, 1]``, ``one of fremen, none``."""
        if self.kind == "options":
            text = "one of " + ", ".join(self.choices)
        elif self.kind == "bool":
            text = "true or false"
        elif self.kind == "pair":
            text = "a pair of numbers (a, b)"
        elif self.kind == "mapping":
            text = "a mapping (Python API only)"
        elif self.kind == "text":
            text = "a text"
        else:
            text = ("an integer" if self.kind == "int" else "a number") + self._range_text()
        return text + (" or none" if self.none_ok else "")

    def _range_text(self) -> str:
        lo_in = self.closed in ("both", "left")
        hi_in = self.closed in ("both", "right")
        if self.low is not None and self.high is not None:
            return f" in {'[' if lo_in else '('}{self.low:g}, {self.high:g}{']' if hi_in else ')'}"
        if self.low is not None:
            return f" {'>=' if lo_in else '>'} {self.low:g}"
        if self.high is not None:
            return f" {'<=' if hi_in else '<'} {self.high:g}"
        return ""

    def is_valid(self, value: Any) -> bool:
        """Whether ``value`` is allowed."""
        if value is None:
            return self.none_ok
        if self.kind == "options":
            return isinstance(value, str) and value in self.choices
        if self.kind == "bool":
            return isinstance(value, bool)
        if self.kind == "mapping":
            return isinstance(value, Mapping)
        if self.kind == "text":
            return isinstance(value, str)
        if self.kind == "pair":
            return (isinstance(value, (tuple, list)) and len(value) == 2
                    and all(_is_real(v) and math.isfinite(float(v)) for v in value))
        if self.kind == "int" and not (isinstance(value, _IntegralNumber) and not isinstance(value, bool)):
            return False
        if not _is_real(value) or math.isnan(float(value)):
            return False
        return self._in_range(float(value))

    def _in_range(self, v: float) -> bool:
        lo_in = self.closed in ("both", "left")
        hi_in = self.closed in ("both", "right")
        if self.low is not None and (v < self.low or (v == self.low and not lo_in)):
            return False
        return not (self.high is not None and (v > self.high or (v == self.high and not hi_in)))

    def check(self, owner: str, name: str, value: Any) -> None:
        """Raise :class:`EstimatorError` ``owner: name must be <describe()>, got <value>`` if invalid."""
        if not self.is_valid(value):
            raise EstimatorError(f"{owner}: {name} must be {self.describe()}, got {value!r}")

    def parse(self, owner: str, name: str, text: str) -> Any:
        """The value of command-line ``text`` (checked); raise :class:`EstimatorError` if it is not allowed."""
        value = self._convert(text.strip())
        if value is _BAD:
            raise EstimatorError(f"{owner}: {name} must be {self.describe()}, got {text!r}")
        self.check(owner, name, value)
        return value

    def _convert(self, text: str) -> Any:
        if self.none_ok and text.lower() in _NONE_WORDS:
            return None
        if self.kind in ("options", "text"):
            return text
        if self.kind == "bool":
            low = text.lower()
            return True if low in _TRUE_WORDS else False if low in _FALSE_WORDS else _BAD
        if self.kind == "mapping":
            return _BAD
        if self.kind == "pair":
            parts = text.strip("()[] ").replace(";", " ").replace("/", " ").split()
            try:
                return tuple(float(p) for p in parts) if len(parts) == 2 else _BAD
            except ValueError:
                return _BAD
        try:
            if self.kind == "int":
                f = float(text)
                return int(f) if f.is_integer() else _BAD
            return float(text)
        except ValueError:
            return _BAD


class _Bad:
    def __repr__(self) -> str:  # pragma: no cover - never shown
        return "<bad>"


_BAD = _Bad()


def _is_real(v: Any) -> bool:
    return isinstance(v, _RealNumber) and not isinstance(v, bool)


def Real(low: float | None = None, high: float | None = None, *, closed: str = "both", none_ok: bool = False,
         help: str = "") -> Param:
    """A real-valued setting in ``[low, high]`` (``closed`` says which bounds are included)."""
    return Param("real", low, high, closed, (), none_ok, help)


def Integral(low: int | None = None, high: int | None = None, *, none_ok: bool = False, help: str = "") -> Param:
    """An integer setting in ``[low, high]``."""
    return Param("int", low, high, "both", (), none_ok, help)


def Options(*choices: str, none_ok: bool = False, help: str = "") -> Param:
    """A string setting with a fixed set of values."""
    return Param("options", choices=tuple(choices), none_ok=none_ok, help=help)


def Boolean(*, help: str = "") -> Param:
    """A true/false setting."""
    return Param("bool", help=help)


def Pair(*, none_ok: bool = False, help: str = "") -> Param:
    """Two finite numbers, e.g. a survival prior's parameters; on the command line ``a/b``."""
    return Param("pair", none_ok=none_ok, help=help)


def Text(*, none_ok: bool = True, help: str = "") -> Param:
    """A string setting (a name or a path)."""
    return Param("text", none_ok=none_ok, help=help)


def MappingParam(*, none_ok: bool = True, help: str = "") -> Param:
    """A mapping (schedules, ground truth): settable from Python only."""
    return Param("mapping", none_ok=none_ok, help=help)


def declared(owner: Any) -> Mapping[str, Param]:
    """The declared settings of an estimator class, instance or factory (empty when it declares none)."""
    params = getattr(owner, "_parameters", None)
    return params if isinstance(params, Mapping) else {}


def check_params(owner_name: str, declarations: Mapping[str, Param], settings: Mapping[str, Any]) -> None:
    """Check every declared setting in ``settings``; raise :class:`EstimatorError` on the first bad one."""
    for key, value in settings.items():
        if key in declarations:
            declarations[key].check(owner_name, key, value)


def parse_setting(owner_name: str, declarations: Mapping[str, Param], key: str, text: str,
                  valid_keys: list[str] | None = None) -> Any:
    """Command-line ``key=text`` as a typed value.

    Declared settings are parsed and checked by their :class:`Param`; settings of estimators that
    declare nothing (plugins) are read as Python literals, else kept as strings.

    Raises:
        EstimatorError: unknown key (lists the valid ones) or a value that is not allowed.
    """
    if valid_keys is not None and key not in valid_keys:
        listing = ", ".join(valid_keys) if valid_keys else "none"
        raise EstimatorError(f"{owner_name}: unknown setting {key!r}; valid settings: {listing}")
    if key in declarations:
        return declarations[key].parse(owner_name, key, text)
    import ast

    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text
