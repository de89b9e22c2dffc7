"""Domains of the configuration fields: declared next to each field, checked in one place.

Every field of a configuration dataclass declares its type and domain where it is defined,
with one of the field helpers of this module, and the class's ``__post_init__`` calls
:func:`check_fields` first::

    @dataclass(frozen=True)
    class RaceConfig:
        dt: float = real(0.1, gt=0.0, unit="s")
        \"\"\"Control period of the plant [s].\"\"\"
        v2v: bool = flag(False)
        ...

        def __post_init__(self) -> None:
            check_fields(self, "race")       # the key path of this class in the env's configuration
            ...                              # then the checks that relate fields to each other

The helpers return ``dataclasses.field(default=..., metadata={"domain": Domain(...)})``, so the
field keeps its default, its annotation and its docstring. The types are strict:

* :func:`flag`: ``True`` or ``False`` only (numpy's bool too); never ``0``, ``1`` or ``"false"``;
* :func:`integer`: an integer (``int`` or a numpy integer), never a bool or a float such as ``2.0``;
* :func:`real`: an ``int`` or a ``float`` (numpy's too), never a bool or a string, and finite: NaN is
  never accepted, ``+inf`` only where the field says what it means (``inf="off"``);
* :func:`reals`: a tuple or list of such numbers (a fixed ``size`` or at least ``min_size`` of them,
  each in the bounds, ``ordered`` ascending where asked);
* :func:`choice`: one of a fixed set of strings; :func:`nested`: an instance of a config class;
  :func:`text`: a string or path; :func:`custom`: a check function of the field's own.

Bounds: ``gt`` / ``ge`` / ``lt`` / ``le`` (> , >=, <, <=). ``optional`` accepts ``None`` (a string
says what None means, e.g. ``"off"``).

:func:`check_fields` raises :class:`~sofar_env.errors.ConfigError` (a ``ValueError``) for the first
field outside its domain, naming the key with its path, what it must be and the value given, e.g.
``race.dt must be a finite number > 0 [s], got nan``. It only reads the object, so a construction
that raises changes nothing. It runs when a configuration is built, never inside an episode.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from collections.abc import Callable
from dataclasses import MISSING, dataclass
from typing import Any

from .errors import ConfigError

__all__ = ["NEUTRAL_KEY", "Domain", "neutral", "is_neutral_default", "real", "integer", "flag", "choice", "reals", "nested", "text", "custom", "check_fields",
           "domain_of", "undeclared_fields", "is_real", "is_integer", "is_bool"]

_KEY = "domain"
NEUTRAL_KEY = "neutral_default"
"""Metadata key of a field declared with :func:`neutral`."""


def is_bool(x: Any) -> bool:
    """``x`` is ``True`` or ``False`` (a Python or numpy bool)."""
    return isinstance(x, bool) or (type(x).__module__ == "numpy" and type(x).__name__ in ("bool_", "bool"))


def is_integer(x: Any) -> bool:
    """``x`` is an integer (Python or numpy), not a bool."""
    return isinstance(x, numbers.Integral) and not is_bool(x)


def is_real(x: Any) -> bool:
    """``x`` is a real number (Python or numpy int or float), not a bool; NaN and inf included."""
    return isinstance(x, numbers.Real) and not is_bool(x)


def _num(x: float) -> str:
    return f"{x:g}"


@dataclass(frozen=True)
class Domain:
    """The type and the values a configuration field accepts (see the module docstring)."""

    kind: str
    """``"real"``, ``"int"``, ``"bool"``, ``"choice"``, ``"reals"``, ``"config"``, ``"text"`` or ``"custom"``."""
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    inf: str | None = None
    """``"real"``: +inf is accepted and means this (e.g. ``"off"``); None: finite only."""
    optional: bool | str = False
    """None is accepted (a string: what None means)."""
    unit: str = ""
    choices: tuple = ()
    size: int | None = None
    min_size: int = 0
    ordered: bool = False
    cls: Any = None
    """``"config"``: the class, or a function returning it (a class imported late)."""
    check: Callable[[Any], str | None] | None = None
    """``"custom"``: returns None for a valid value, else the reason it is not."""
    describe_as: str = ""

    # ------------------------------------------------------------------ text
    def _bounds(self) -> str:
        lo = ("(", self.gt) if self.gt is not None else ("[", self.ge) if self.ge is not None else None
        hi = (")", self.lt) if self.lt is not None else ("]", self.le) if self.le is not None else None
        if lo and hi:
            return f" in {lo[0]}{_num(lo[1])}, {_num(hi[1])}{hi[0]}"
        if lo:
            return f" {'>' if lo[0] == '(' else '>='} {_num(lo[1])}"
        if hi:
            return f" {'<' if hi[0] == ')' else '<='} {_num(hi[1])}"
        return ""

    def describe(self) -> str:
        """What the field must be, in words (the end of the error message)."""
        unit = f" [{self.unit}]" if self.unit else ""
        if self.kind == "bool":
            out = "True or False"
        elif self.kind == "int":
            out = f"an integer{self._bounds()}"
        elif self.kind == "real":
            out = f"{'a number' if self.inf else 'a finite number'}{self._bounds()}{unit}"
            if self.inf:
                out += f" (inf: {self.inf})"
        elif self.kind == "reals":
            count = f"{self.size} " if self.size is not None else (
                f"at least {self.min_size} " if self.min_size else "")
            out = f"a sequence of {count}finite numbers{self._bounds()}{unit}"
            if self.ordered:
                out += " in ascending order"
        elif self.kind == "choice":
            out = "one of " + ", ".join(map(repr, self.choices))
        elif self.kind == "config":
            out = f"a {self._class().__name__} (or a mapping of its keys)"
        elif self.kind == "text":
            out = "a string or a path"
        else:
            out = self.describe_as or "valid"
        if self.optional:
            out = f"None{' (' + self.optional + ')' if isinstance(self.optional, str) else ''} or {out}"
        return out

    def _class(self) -> type:
        return self.cls if isinstance(self.cls, type) else self.cls()

    # ------------------------------------------------------------------ check
    def _in_bounds(self, x: Any) -> bool:
        return ((self.gt is None or x > self.gt) and (self.ge is None or x >= self.ge)
                and (self.lt is None or x < self.lt) and (self.le is None or x <= self.le))

    def _real_ok(self, x: Any, allow_inf: bool) -> bool:
        if not is_real(x) or math.isnan(x):
            return False
        if math.isinf(x):
            return allow_inf and x > 0 and (self.lt is None and self.le is None)
        return self._in_bounds(x)

    def reason(self, value: Any) -> str | None:
        """None when ``value`` lies in the domain, else why not (``"must be ..."`` or a custom reason)."""
        if value is None and self.optional:
            return None
        kind = self.kind
        if kind == "bool":
            ok = is_bool(value)
        elif kind == "int":
            ok = is_integer(value) and self._in_bounds(value)
        elif kind == "real":
            ok = self._real_ok(value, self.inf is not None)
        elif kind == "reals":
            ok = (isinstance(value, (tuple, list)) and (self.size is None or len(value) == self.size)
                  and len(value) >= self.min_size and all(self._real_ok(x, False) for x in value)
                  and (not self.ordered or all(a <= b for a, b in zip(value, value[1:]))))
        elif kind == "choice":
            ok = isinstance(value, str) and value in self.choices
        elif kind == "config":
            ok = isinstance(value, self._class())
        elif kind == "text":
            ok = isinstance(value, (str, os.PathLike))
        else:
            assert self.check is not None
            return self.check(value)
        return None if ok else f"must be {self.describe()}"


def _field(default: Any, domain: Domain, factory: Callable[[], Any] | None = None) -> Any:
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata={_KEY: domain})
    return dataclasses.field(default=default, metadata={_KEY: domain})


def neutral(f: Any) -> Any:
    """Mark a field as *neutral at its default*: added after results were made, with a default that keeps
    the behaviour those results had (a fix switched off, a new term weighted 0). While it holds its default
    it is left out of the configuration hash (:mod:`sofar_env.config_hash`), so adding it does not re-label
    every committed table; set to any other value, it is hashed like every field. Wraps a field helper::

        restart_lateral_weight: float = neutral(real(0.0, ge=0.0))
    """
    if not isinstance(f, dataclasses.Field) or f.default is MISSING:
        raise TypeError("neutral() wraps a field helper with a plain default, e.g. neutral(real(0.0))")
    return dataclasses.field(default=f.default, metadata={**f.metadata, NEUTRAL_KEY: True})


def is_neutral_default(f: dataclasses.Field, value: Any) -> bool:
    """Whether ``value`` of field ``f`` is the default of a field declared with :func:`neutral`."""
    if not f.metadata.get(NEUTRAL_KEY):
        return False
    same = value == f.default
    return same is True or (type(same).__module__ == "numpy" and getattr(same, "ndim", 1) == 0 and bool(same))


def real(default: Any = MISSING, *, gt: float | None = None, ge: float | None = None, lt: float | None = None,
         le: float | None = None, inf: str | None = None, optional: bool | str = False, unit: str = "") -> Any:
    """A real-number field (int or float, finite unless ``inf`` says what +inf means) within the bounds."""
    return _field(default, Domain("real", gt=gt, ge=ge, lt=lt, le=le, inf=inf, optional=optional, unit=unit))


def integer(default: Any = MISSING, *, ge: int | None = None, le: int | None = None,
            optional: bool | str = False) -> Any:
    """An integer field (not a bool, not a float) within the bounds."""
    return _field(default, Domain("int", ge=ge, le=le, optional=optional))


def flag(default: bool) -> Any:
    """A bool field: True or False only."""
    return _field(default, Domain("bool"))


def choice(default: str, choices: tuple[str, ...]) -> Any:
    """A string field that takes one of ``choices``."""
    return _field(default, Domain("choice", choices=tuple(choices)))


def reals(default: Any, *, size: int | None = None, min_size: int = 0, gt: float | None = None,
          ge: float | None = None, lt: float | None = None, le: float | None = None, ordered: bool = False,
          unit: str = "") -> Any:
    """A tuple (or list) of finite real numbers, each within the bounds."""
    return _field(default, Domain("reals", size=size, min_size=min_size, gt=gt, ge=ge, lt=lt, le=le,
                                  ordered=ordered, unit=unit))


def nested(cls: Any, *, default: Any = MISSING, factory: Callable[[], Any] | None = None,
           optional: bool | str = False) -> Any:
    """A sub-configuration: an instance of ``cls`` (a class, or a function returning it); the default is
    ``cls()`` unless ``default`` or ``factory`` is given."""
    if default is MISSING and factory is None:
        factory = cls
    return _field(default, Domain("config", cls=cls, optional=optional), factory)


def text(default: Any = MISSING, *, optional: bool | str = False) -> Any:
    """A string (or ``os.PathLike``) field."""
    return _field(default, Domain("text", optional=optional))


def custom(default: Any, check: Callable[[Any], str | None], describe: str) -> Any:
    """A field checked by ``check(value)``: None when valid, else the reason (the message after the key)."""
    return _field(default, Domain("custom", check=check, describe_as=describe))


def domain_of(cls_or_obj: Any, name: str) -> Domain | None:
    """The declared :class:`Domain` of field ``name`` (None when it declares none)."""
    for f in dataclasses.fields(cls_or_obj):
        if f.name == name:
            return f.metadata.get(_KEY)
    raise KeyError(name)


def undeclared_fields(cls_or_obj: Any) -> list[str]:
    """The fields of a config dataclass that declare no domain (every field should declare one)."""
    return [f.name for f in dataclasses.fields(cls_or_obj) if _KEY not in f.metadata]


def check_fields(obj: Any, path: str = "") -> None:
    """Raise :class:`ConfigError` for the first field of ``obj`` outside its declared domain.

    ``path`` is the key path of ``obj`` in the environment's configuration (``"race"``,
    ``"stack.mpc"``; ``""`` at the top); the message names ``path.field``. Reads only.
    """
    for f in dataclasses.fields(obj):
        domain = f.metadata.get(_KEY)
        if domain is None:
            continue
        value = getattr(obj, f.name)
        why = domain.reason(value)
        if why is not None:
            key = f"{path}.{f.name}" if path else f.name
            typed = "" if is_real(value) or value is None or isinstance(value, (tuple, list)) else (
                f" ({type(value).__name__})")
            if domain.kind == "custom":
                raise ConfigError(f"{key}: {why}")
            raise ConfigError(f"{key} {why}, got {value!r}{typed}")
