"""Declared settings: types, ranges and formats, checked before any work (scikit-learn's
``_parameter_constraints`` habit). One schema for every setting a user can type: estimator
settings (``psg-eval -e NAME:key=value``), conversion options and config keys
(:data:`psg_data.convert.CONVERT_SETTINGS`), ``synth`` and ``label`` options.

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
naming the setting, the value and what is allowed. :func:`check_settings` checks a whole mapping
(a config file's content, command-line options) and raises the caller's error class.

Real settings may be declared ``finite`` (NaN and infinities refused whatever the range); integer
ranges are compared exactly (a 30-digit integer is refused, not overflowed); ``timezone`` settings
hold an IANA name; ``reals`` settings a list of ``length`` finite numbers; ``text`` settings may
carry a ``form`` check (a parser of structured text such as ``gap:SECONDS``) that returns what is
wrong or None.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from numbers import Integral as _IntegralNumber
from numbers import Real as _RealNumber
from typing import Any

from psg_data.errors import EstimatorError, PsgDataError

__all__ = ["Param", "Real", "Integral", "Options", "Boolean", "Pair", "MappingParam", "Text", "TimeZone", "Reals",
           "Records", "check_params", "check_settings", "parse_setting", "shown", "INT64_MAX", "STAMP_MAX_NS",
           "DURATION_MAX_S"]

INT64_MAX = 2**63 - 1
STAMP_MAX_NS = 2**62
"""Largest stamp a recording or setting may carry, ns since the epoch (2116-02-20): int64 with room
for any stamp plus a duration of :data:`DURATION_MAX_S`."""
DURATION_MAX_S = 365 * 86400.0
"""Largest duration setting (tolerances, gaps, slots, buffers), seconds: one year."""

_NONE_WORDS = ("none", "null")
_TRUE_WORDS = ("true", "yes", "on", "1")
_FALSE_WORDS = ("false", "no", "off", "0")


@dataclass(frozen=True)
class Param:
    """One declared setting.

    Attributes:
        kind: "real", "int", "options", "bool", "pair" (two reals), "text" (a string, e.g. a path),
            "timezone" (an IANA name), "reals" (``length`` finite numbers), "records" (a list whose
            items ``form`` checks) or "mapping" (Python API only).
        low, high: bounds of "real" / "int" values (None: unbounded on that side).
        closed: which bounds are included: "both", "left", "right" or "neither".
        choices: allowed values of an "options" setting.
        none_ok: None is allowed (typically "estimate it from the data").
        help: one line for listings (units included).
        finite: "real": NaN and infinities are refused.
        length: "reals": how many numbers.
        form: "text" / "records": what is wrong with a value of the right type (None: nothing).
        expected: what is allowed, in words (replaces :meth:`describe`'s own text).
    """

    kind: str
    low: float | None = None
    high: float | None = None
    closed: str = "both"
    choices: tuple[str, ...] = ()
    none_ok: bool = False
    help: str = ""
    finite: bool = False
    length: int = 0
    form: Callable[[Any], str | None] | None = None
    expected: str = ""

    def describe(self) -> str:
        """What is allowed, in words: ``a number in [0, 1]``, ``one of fremen, none``."""
        if self.expected:
            text = self.expected
        elif self.kind == "options":
            text = "one of " + ", ".join(self.choices)
        elif self.kind == "bool":
            text = "true or false"
        elif self.kind == "pair":
            text = "a pair of numbers (a, b)"
        elif self.kind == "mapping":
            text = "a mapping (Python API only)"
        elif self.kind == "text":
            text = "a text"
        elif self.kind == "timezone":
            text = "an IANA time zone name such as UTC or Europe/Berlin"
        elif self.kind == "reals":
            text = f"a list of {self.length} finite numbers"
        else:
            text = ("an integer" if self.kind == "int" else "a finite number" if self.finite else "a number") \
                + self._range_text()
        return text + (" or none" if self.none_ok else "")

    def _range_text(self) -> str:
        lo_in = self.closed in ("both", "left")
        hi_in = self.closed in ("both", "right")
        lo, hi = _bound(self.low), _bound(self.high)
        if self.low is not None and self.high is not None:
            return f" in {'[' if lo_in else '('}{lo}, {hi}{']' if hi_in else ')'}"
        if self.low is not None:
            return f" {'>=' if lo_in else '>'} {lo}"
        if self.high is not None:
            return f" {'<=' if hi_in else '<'} {hi}"
        return ""

    def is_valid(self, value: Any) -> bool:
        """Whether ``value`` is allowed."""
        return self.problem(value) is None

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` (None: it is allowed); usually :meth:`describe` itself."""
        if value is None:
            return None if self.none_ok else self.describe()
        if not self._of_kind(value):
            return self.describe()
        if self.form is not None:
            return self.form(value)
        return None

    def _of_kind(self, value: Any) -> bool:
        if self.kind == "options":
            return isinstance(value, str) and value in self.choices
        if self.kind == "bool":
            return isinstance(value, bool)
        if self.kind == "mapping":
            return isinstance(value, Mapping)
        if self.kind == "text":
            return isinstance(value, str)
        if self.kind == "timezone":
            return isinstance(value, str) and _is_timezone(value)
        if self.kind == "records":
            return isinstance(value, (list, tuple))
        if self.kind == "reals":
            return (isinstance(value, (tuple, list)) and len(value) == self.length
                    and all(_is_real(v) and math.isfinite(float(v)) for v in value))
        if self.kind == "pair":
            return (isinstance(value, (tuple, list)) and len(value) == 2
                    and all(_is_real(v) and math.isfinite(float(v)) for v in value))
        if self.kind == "int":
            return isinstance(value, _IntegralNumber) and not isinstance(value, bool) and self._in_range(int(value))
        if not _is_real(value):
            return False
        try:
            v = float(value)
        except OverflowError:  # a Fraction / Decimal beyond float range
            return False
        if math.isnan(v) or (self.finite and not math.isfinite(v)):
            return False
        return self._in_range(v)

    def _in_range(self, v: float | int) -> bool:
        lo_in = self.closed in ("both", "left")
        hi_in = self.closed in ("both", "right")
        if self.low is not None and (v < self.low or (v == self.low and not lo_in)):
            return False
        return not (self.high is not None and (v > self.high or (v == self.high and not hi_in)))

    def check(self, owner: str, name: str, value: Any) -> None:
        """Raise :class:`EstimatorError` ``owner: name must be <describe()>, got <value>`` if invalid."""
        why = self.problem(value)
        if why is not None:
            raise EstimatorError(f"{owner}: {name} must be {why}, got {shown(value)}")

    def parse(self, owner: str, name: str, text: str) -> Any:
        """The value of command-line ``text`` (checked); raise :class:`EstimatorError` if it is not allowed."""
        value = self._convert(text.strip())
        if value is _BAD:
            raise EstimatorError(f"{owner}: {name} must be {self.describe()}, got {shown(text)}")
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
        if self.kind in ("timezone",):
            return text
        try:
            if self.kind == "int":
                try:
                    return int(text)
                except ValueError:
                    f = float(text)
                    return int(f) if f.is_integer() else _BAD
            return float(text)
        except (ValueError, OverflowError):
            return _BAD


def _bound(v: float | None) -> str:
    """A range bound as typed: exact for integers (``4611686018427387904``), else ``%g``."""
    if v is None:
        return ""
    if isinstance(v, int) or (float(v).is_integer() and abs(v) < 1e16):
        return str(int(v))
    return f"{v:g}"


class _Bad:
    def __repr__(self) -> str:  # pragma: no cover - never shown
        return "<bad>"


_BAD = _Bad()


def _is_real(v: Any) -> bool:
    return isinstance(v, _RealNumber) and not isinstance(v, bool)


def _is_timezone(name: str) -> bool:
    if not name or name != name.strip() or "\0" in name:
        return False
    from zoneinfo import ZoneInfo

    try:
        ZoneInfo(name)
    except (ValueError, OSError, KeyError):  # ZoneInfoNotFoundError is a KeyError; bad names ValueError
        return False
    return True


_SHOWN_MAX = 60


def shown(value: Any) -> str:
    """``repr(value)`` cut to a readable length (a 400-digit integer stays one short line)."""
    text = repr(value)
    return text if len(text) <= _SHOWN_MAX else f"{text[:_SHOWN_MAX - 3]}..."


def Real(low: float | None = None, high: float | None = None, *, closed: str = "both", none_ok: bool = False,
         help: str = "", finite: bool = False) -> Param:
    """A real-valued setting in ``[low, high]`` (``closed`` says which bounds are included)."""
    return Param("real", low, high, closed, (), none_ok, help, finite=finite)


def Integral(low: int | None = None, high: int | None = None, *, none_ok: bool = False, help: str = "") -> Param:
    """An integer setting in ``[low, high]`` (compared exactly)."""
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


def Text(*, none_ok: bool = True, help: str = "", form: Callable[[Any], str | None] | None = None,
         expected: str = "") -> Param:
    """A string setting (a name or a path); ``form`` checks its structure (returns what is wrong)."""
    return Param("text", none_ok=none_ok, help=help, form=form, expected=expected)


def TimeZone(*, none_ok: bool = True, help: str = "") -> Param:
    """An IANA time zone name (one the machine's zone database knows)."""
    return Param("timezone", none_ok=none_ok, help=help)


def Reals(length: int, *, none_ok: bool = True, help: str = "") -> Param:
    """A list of ``length`` finite numbers."""
    return Param("reals", none_ok=none_ok, help=help, length=length)


def Records(form: Callable[[Any], str | None], *, expected: str, help: str = "") -> Param:
    """A list whose items ``form`` checks (returns what is wrong with the list, or None)."""
    return Param("records", help=help, form=form, expected=expected)


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


def check_settings(declarations: Mapping[str, Param], settings: Mapping[str, Any], where: str,
                   error: type[PsgDataError], names: Mapping[str, str] | None = None) -> None:
    """Check every declared key of ``settings``; raise ``error`` on the first bad value, as one line
    ``WHERE: KEY: expected WHAT, got VALUE`` (``names`` maps a key to how the user typed it, e.g.
    ``--sync-tolerance``, shown with the key).
    """
    for key, value in settings.items():
        param = declarations.get(key)
        if param is None:
            continue
        why = param.problem(value)
        if why is not None:
            typed = (names or {}).get(key)
            label = f"{typed} ({key})" if typed and typed != key else key
            raise error(f"{where}: {label}: expected {why}, got {shown(value)}")


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
