"""The shared validator: declarative field specs and one walk that checks a document.

Every input a user writes by hand goes through :func:`validate`: the env
configuration (:mod:`hasa_env.sim.config`), steering-model files
(:mod:`hasa_env.steering.model_file`), input-device calibrations
(:mod:`hasa_env.devices.calibration`), recording sidecars
(:mod:`hasa_env.recording.format`), drive settings
(:mod:`hasa_env.session.settings`) and, in the layers above, the benchmark's protocol
settings. A schema is a tree of :class:`Field` specs;
:func:`validate` walks a nested document against it, fills in defaults,
rejects unknown keys (naming the allowed ones), converts what it accepts
(numpy scalars to Python numbers, integral floats to ``int`` for integer
fields, numbers to ``float`` for number fields, tuples and 1-D arrays to
lists) and raises the caller's own error class.

Every message is one sentence about one key path, whose subject the caller
names (``describe(path)``: ``"config key 'noise.camera'"``, ``"field 'dt'"``):

- ``<subject> must be <allowed>, got <value>``: wrong type, or outside a
  one-sided bound (``must be a finite positive number, got -0.01``);
- ``<subject> = <value> is out of range: allowed <range>``: outside an
  interval with two finite ends (``allowed [0, 10] m``, ``allowed integers [1, 1000]``);
- ``<subject> = <value> is not allowed: one of 'a', 'b'`` (a choice);
- ``<subject> is missing`` (a required key);
- ``unknown <subject> (allowed keys here: a, b, c)`` (``; did you mean 'b'?``: :func:`did_you_mean`);
- ``<subject> has the entry <v> twice (...)`` (a list of distinct entries), and
  ``<subject> is nested more than N levels deep`` (free JSON).

A field's :meth:`Field.allowed` text is the ``<allowed>`` of these messages and
what :func:`hasa_env.sim.config.describe_config` prints.

Why one small validator and not pydantic (decided for the issue "A house a
newcomer can read", which found seven hand-written validators in four styles):

- the messages are part of the user-facing contract and of the tests: they
  name the key path, the allowed range with its unit, and the value given,
  in one format for every file; pydantic's messages have their own format
  and would need translating back;
- every ``gym.make`` validates a configuration, so validation must stay
  cheap: this walk is a few dozen ``isinstance`` checks per call;
- the rules are the project's own: a bool is not a number, numpy scalars
  are numbers, only finite floats, an integer beyond the float range is out
  of range (not an ``OverflowError``), a string is not a list, an array is
  not a choice, free JSON has a depth cap;
- the core install gains no dependency.

Why this module is long: it is the one walk over every kind of field and the messages of
each; split, the one message format would be split too.

This module sits in the bottom layer of :mod:`hasa_env` (docs/design.md §2.2)
and imports nothing from the project.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import os
import re
import reprlib
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

import numpy as np

__all__ = [
    "ABSENT",
    "ANY_JSON",
    "KINDS",
    "REQUIRED",
    "Field",
    "schema",
    "did_you_mean",
    "show",
    "validate",
    "validate_fields",
    "version",
]

KINDS = (
    "number", "integer", "bool", "choice", "string", "numbers", "integers", "strings", "mapping",
    "json",
)  # fmt: skip
"""The kinds of :class:`Field`:

``number`` a finite float; ``integer`` an int; ``bool`` true or false;
``choice`` one of ``choices`` (same type and value); ``string`` a str;
``numbers`` a list of finite floats; ``integers`` a list of ints;
``strings`` a list of non-empty strs;
``mapping`` an object with the keys of ``fields``, or any string keys
whose values each satisfy ``each``; ``json`` free JSON data.
"""

_FLOAT_MAX = sys.float_info.max
_AWKWARD = re.compile(r"[.\[\]'\s]")


class _Marker:
    def __init__(self, name: str) -> None:
        self._name = name

    def __repr__(self) -> str:
        return self._name


REQUIRED: Any = _Marker("REQUIRED")
"""Default of a field that must be given (missing: ``<subject> is missing``)."""

ABSENT: Any = _Marker("ABSENT")
"""Default of a field that may be left out and then stays out of the result."""

_repr = reprlib.Repr()
_repr.maxlevel = 3
_repr.maxstring = 60
_repr.maxother = 60
_repr.maxlist = _repr.maxtuple = _repr.maxdict = _repr.maxset = 6
_repr.maxlong = 40


def show(value: Any) -> str:
    """A short ``repr`` of ``value`` for a message: bounded in depth and length, never raising."""
    if type(value) is int and abs(value) >= 10**30:
        digits = int(math.log10(abs(value))) + 1  # str() of a huge int is slow, or refused
        return f"<an integer of about {digits} digits>"
    try:
        return _repr.repr(value)
    except Exception:  # a hostile __repr__, or one that recurses too deep
        return f"<{type(value).__name__} object>"


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the choice closest to a misspelt ``word``, or ``""``
    when none is close (:func:`difflib.get_close_matches`, cutoff 0.6)."""
    close = difflib.get_close_matches(word, [str(c) for c in choices], n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def _number_text(x: float) -> str:
    return f"{x:g}"


@dataclasses.dataclass(frozen=True, slots=True)
class Field:
    """What one key of a document may hold.

    Attributes:
        kind: one of :data:`KINDS`.
        default: the value a missing key takes; :data:`REQUIRED` (missing is
            an error) or :data:`ABSENT` (missing stays missing). For a
            ``mapping`` with ``fields`` the default (usually ``{}``) is
            validated, so its fields' defaults fill in; other defaults are
            taken as they are (a deep copy), so ``None`` can mean "not given"
            for a field that does not accept null.
        doc: what the value is, for listings such as ``describe_config``.
        unit: unit of a number (``"m"``, ``"m/s^2"``); printed after a range.
        low, high: bounds of a number, an integer or each entry of ``numbers``
            (None: unbounded on that side).
        low_open, high_open: True: the bound itself is not allowed.
        infinite: a ``number`` may also be an infinity its bounds allow (``inf``
            as "no limit"); NaN never is.
        choices: the allowed values of a ``choice``.
        optional: None (JSON null) is allowed too.
        unique: the entries of a ``numbers`` or ``strings`` list must differ.
        non_empty: a string, list or mapping must not be empty.
        max_length: the most characters of a string, entries of a list or
            keys of a mapping, or values (at all levels) of free JSON.
        max_depth: the most levels of lists and objects in free JSON.
        pattern: a string must match this regular expression in full.
        pattern_doc: what ``pattern`` allows, in words (for messages).
        fields: a ``mapping``'s keys and their specs.
        each: the spec of every value of a ``mapping`` with free string keys.
        hint: advice added to every message about this field's value.
    """

    kind: str
    default: Any = REQUIRED
    doc: str = ""
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    infinite: bool = False
    choices: tuple[Any, ...] = ()
    optional: bool = False
    unique: bool = False
    non_empty: bool = False
    max_length: int | None = None
    max_depth: int = 16
    pattern: re.Pattern[str] | None = None
    pattern_doc: str = ""
    fields: Mapping[str, Field] | None = None
    each: Field | None = None
    hint: str = ""
    item: Field | None = dataclasses.field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"Field.kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if (self.fields is not None or self.each is not None) != (self.kind == "mapping") or (
            self.fields is not None and self.each is not None
        ):
            raise ValueError("a 'mapping' Field needs exactly one of fields= and each=")
        if (self.kind == "choice") != bool(self.choices):
            raise ValueError("a 'choice' Field needs choices=, and only a choice has them")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"Field bounds low = {self.low!r} > high = {self.high!r}")
        if self.kind in ("numbers", "integers"):
            entry = Field("number" if self.kind == "numbers" else "integer", low=self.low,
                          high=self.high, unit=self.unit, low_open=self.low_open,
                          high_open=self.high_open)  # fmt: skip
            object.__setattr__(self, "item", entry)
        elif self.kind == "strings":
            object.__setattr__(self, "item", Field("string", non_empty=True))

    # ------------------------------------------------------------ texts
    def _two_sided(self) -> bool:
        return self.low is not None and self.high is not None

    def range_text(self) -> str:
        """The interval or bound of a number, integer or list entry (``"[0, 10] m"``, ``">= 1"``)."""
        unit = f" {self.unit}" if self.unit else ""
        if self._two_sided():
            left = "(" if self.low_open else "["
            right = ")" if self.high_open else "]"
            assert self.low is not None and self.high is not None
            text = f"{left}{_number_text(self.low)}, {_number_text(self.high)}{right}"
        elif self.low is not None:
            text = f"{'>' if self.low_open else '>='} {_number_text(self.low)}"
        elif self.high is not None:
            text = f"{'<' if self.high_open else '<='} {_number_text(self.high)}"
        else:
            return ""
        return text + unit

    def _number_noun(self, plural: bool) -> str:
        integer = self.kind == "integer"
        if integer and self.low == 1 and not self.low_open and self.high is None:
            return "positive integers" if plural else "a positive integer"
        if self.low == 0 and self.high is None:
            sign = "positive" if self.low_open else "non-negative"
            if integer:
                return f"{sign} integers" if plural else f"a {sign} integer"
            if self.infinite:
                return f"{sign} numbers or inf" if plural else f"a {sign} number or inf"
            return f"finite {sign} numbers" if plural else f"a finite {sign} number"
        finite = "" if self.infinite else "finite "
        noun = ("integers" if plural else "an integer") if integer else (
            f"{finite}numbers" if plural else f"a {finite}number"
        )  # fmt: skip
        rng = self.range_text()
        if rng:
            noun = f"{noun} in {rng}" if self._two_sided() else f"{noun} {rng}"
        return f"{noun} (infinities included)" if self.infinite else noun

    def allowed(self) -> str:
        """What this field accepts, in words (the ``<allowed>`` of the messages)."""
        kind = self.kind
        if kind in ("number", "integer"):
            text = self._number_noun(plural=False)
        elif kind == "bool":
            text = "true or false"
        elif kind == "choice":
            shown = ", ".join(show(c) for c in self.choices)
            text = f"only {shown}" if len(self.choices) == 1 else f"one of {shown}"
        elif kind == "string":
            text = "a non-empty string" if self.non_empty else "a string"
            if self.max_length is not None:
                text += f" of at most {self.max_length} characters"
            if self.pattern_doc:
                text += f" ({self.pattern_doc})"
        elif kind in ("numbers", "integers", "strings"):
            assert self.item is not None
            head = "a non-empty list of " if self.non_empty else "a list of "
            if self.unique:
                head += "distinct "
            if kind != "strings":
                entries = self.item._number_noun(plural=True)
            else:
                entries = "non-empty strings"
            text = head + entries
            if self.max_length is not None:
                text += f" (at most {self.max_length})"
        elif kind == "mapping":
            text = "a mapping (JSON object)"
            if self.each is not None and self.each.kind != "json":
                text += f" of string keys to values that are each {self.each.allowed()}"
        else:
            text = (
                "JSON data (null, true or false, finite numbers, strings, lists, objects with "
                f"string keys; at most {self.max_depth} levels deep)"
            )
        return text + (" or null" if self.optional else "")

    def leaves(self, prefix: str = "") -> Iterator[tuple[str, Field]]:
        """Every leaf below a ``mapping`` with ``fields``, as (key path, field), in schema order."""
        for key, sub in (self.fields or {}).items():
            path = f"{prefix}{key}"
            if sub.fields is not None:
                yield from sub.leaves(path + ".")
            else:
                yield path, sub


ANY_JSON = Field("json")
"""Free JSON data, at most 16 levels deep."""


def schema(fields: Mapping[str, Field | Mapping[str, Any]], doc: str = "") -> Field:
    """A ``mapping`` Field from ``fields``; a nested plain mapping is a group defaulting to ``{}``.

    ``schema({"noise": {"camera": Field("number", 0.05)}})`` is the mapping
    whose key ``noise`` is a mapping (missing: its fields' defaults) with the
    key ``camera``.
    """
    converted: dict[str, Field] = {}
    for key, value in fields.items():
        converted[key] = value if isinstance(value, Field) else schema(value)
    return Field("mapping", default={}, doc=doc, fields=converted)


def version(current: int, doc: str = "", default: Any = REQUIRED) -> Field:
    """The format-version field of a file this hasa_env reads in version ``current`` only."""
    return Field("choice", default, doc or "format version", choices=(current,),
                 hint="the version this hasa_env reads")  # fmt: skip


Describe = Callable[[str], str]
"""Key path -> the subject of a message (``"config key 'noise.camera'"``); ``""`` is the document."""

MakeError = Callable[[str, str], Exception]
"""(key path, message) -> the exception to raise."""


def validate(
    document: Any,
    spec: Field | Mapping[str, Any],
    *,
    describe: Describe,
    error: MakeError,
    path: str = "",
) -> Any:
    """Check ``document`` against ``spec`` and return the converted value.

    Args:
        document: the value to check (a nested mapping, usually parsed JSON).
        spec: a :class:`Field`, or a mapping of fields (as for :func:`schema`).
        describe: names the key at a path for the messages
            (``lambda p: f"config key '{p}'"``); called with ``""`` for the
            document itself.
        error: builds the exception to raise from (path, message), e.g.
            ``lambda path, message: ConfigError(message)``.
        path: the key path of ``document`` inside a larger document.

    Returns:
        The accepted value: dicts and lists built anew (defaults filled in,
        keys left out with :data:`ABSENT` omitted), numbers converted.

    Raises:
        Whatever ``error`` returns, for the first problem found: fields in
        schema order, then a mapping's unknown keys.
    """
    field = spec if isinstance(spec, Field) else schema(spec)
    return _Walk(describe, error).check(document, field, path)


def validate_fields(
    instance: Any, spec: Field | Mapping[str, Any], *, describe: Describe, error: MakeError
) -> None:
    """Validate a dataclass instance's fields against ``spec`` and store the converted values.

    For ``__post_init__``: every field of the dataclass must be in ``spec``;
    frozen dataclasses work too. Raises what ``error`` returns.
    """
    given = {f.name: getattr(instance, f.name) for f in dataclasses.fields(instance)}
    for name, value in validate(given, spec, describe=describe, error=error).items():
        object.__setattr__(instance, name, value)


def _join(path: str, key: Any) -> str:
    """``path.key``; a key that is empty, not a str or holds ``.[]'`` is written ``path[repr]``."""
    if isinstance(key, str) and key and not _AWKWARD.search(key):
        return f"{path}.{key}" if path else key
    return f"{path}[{show(key)}]"


def _as_number(value: Any) -> int | float | None:
    """A Python int or float for a number (numpy scalars included), None for anything else."""
    kind = type(value)
    if kind is float or kind is int:
        return value
    if isinstance(value, bool | np.bool_):
        return None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    if isinstance(value, int):
        return int(value)
    return None


class _Walk:
    """One validation: the caller's message subject and error class, and the checks per kind."""

    __slots__ = ("describe", "error", "_budget")

    def __init__(self, describe: Describe, error: MakeError) -> None:
        self.describe = describe
        self.error = error
        self._budget = 0

    def fail(self, path: str, field: Field | None, predicate: str) -> Exception:
        message = f"{self.describe(path)} {predicate}"
        if field is not None and field.hint:
            message += f" ({field.hint})"
        return self.error(path, message)

    def must(self, path: str, field: Field, value: Any, got: str | None = None) -> Exception:
        return self.fail(path, field, f"must be {field.allowed()}, got {got or show(value)}")

    def check(self, value: Any, field: Field, path: str) -> Any:
        if value is None and field.optional:
            return None
        return _CHECKS[field.kind](self, value, field, path)

    # ----------------------------------------------------------- scalars
    def _bounds(self, x: int | float, field: Field, path: str) -> None:
        low, high = field.low, field.high
        below = low is not None and (x <= low if field.low_open else x < low)
        above = high is not None and (x >= high if field.high_open else x > high)
        if below or above:
            if field._two_sided():
                noun = "integers " if field.kind == "integer" else ""
                raise self.fail(
                    path, field, f"= {show(x)} is out of range: allowed {noun}{field.range_text()}"
                )
            raise self.must(path, field, x)
        if type(x) is int and abs(x) > _FLOAT_MAX:
            raise self.fail(
                path,
                field,
                f"= {show(x)} is out of range: numbers beyond +-{_FLOAT_MAX:.4g} (the float "
                "range) are not allowed",
            )

    def number(self, value: Any, field: Field, path: str) -> float:
        x = _as_number(value)
        if x is None or (
            type(x) is float and not math.isfinite(x) and (math.isnan(x) or not field.infinite)
        ):
            raise self.must(path, field, value)
        self._bounds(x, field, path)
        return float(x)

    def integer(self, value: Any, field: Field, path: str) -> int:
        x = _as_number(value)
        if isinstance(x, float):  # (exactly a float: _as_number converts)
            if not (math.isfinite(x) and x.is_integer()):
                raise self.must(path, field, value)
            x = int(x)
        if x is None:
            raise self.must(path, field, value)
        self._bounds(x, field, path)
        return x

    def boolean(self, value: Any, field: Field, path: str) -> bool:
        if isinstance(value, bool | np.bool_):
            return bool(value)
        raise self.must(path, field, value)

    def choice(self, value: Any, field: Field, path: str) -> Any:
        plain = value.item() if isinstance(value, np.generic) else value
        for allowed in field.choices:
            if type(plain) is type(allowed) and plain == allowed:
                return allowed
        raise self.fail(path, field, f"= {show(value)} is not allowed: {field.allowed()}")

    def string(self, value: Any, field: Field, path: str) -> str:
        if not isinstance(value, str):
            raise self.must(path, field, value)
        text = str(value)
        if field.non_empty and not text:
            raise self.must(path, field, value)
        if field.max_length is not None and len(text) > field.max_length:
            raise self.must(path, field, value, f"{show(text)} ({len(text)} characters)")
        if field.pattern is not None and not field.pattern.fullmatch(text):
            raise self.must(path, field, value)
        return text

    # ------------------------------------------------------------- lists
    def _entries(self, value: Any, field: Field, path: str) -> list[Any]:
        if isinstance(value, list | tuple):
            entries = list(value)
        elif isinstance(value, np.ndarray) and value.ndim == 1:
            entries = value.tolist()
        else:
            raise self.must(path, field, value)
        if field.non_empty and not entries:
            raise self.must(path, field, value, "an empty list")
        if field.max_length is not None and len(entries) > field.max_length:
            raise self.must(path, field, value, f"a list of {len(entries)} entries")
        return entries

    def _distinct(self, entries: list[Any], field: Field, path: str) -> None:
        first: dict[Any, int] = {}
        for i, entry in enumerate(entries):
            j = first.setdefault(entry, i)
            if j != i:
                raise self.fail(
                    path,
                    field,
                    f"has the entry {show(entries[j])} twice (at [{j}] and [{i}]); entries must be "
                    "distinct",
                )

    def listing(self, value: Any, field: Field, path: str) -> list[Any]:
        """A ``numbers``, ``integers`` or ``strings`` list: each entry checked as ``field.item``."""
        assert field.item is not None
        entry = {"numbers": self.number, "integers": self.integer}.get(field.kind, self.string)
        entries = self._entries(value, field, path)
        out = [entry(v, field.item, f"{path}[{i}]") for i, v in enumerate(entries)]
        if field.unique:
            self._distinct(out, field, path)
        return out

    # ---------------------------------------------------------- mappings
    def mapping(self, value: Any, field: Field, path: str) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise self.must(path, field, value)
        if field.non_empty and not value:
            raise self.must(path, field, value, "an empty mapping")
        if field.max_length is not None and len(value) > field.max_length:
            raise self.must(path, field, value, f"a mapping of {len(value)} keys")
        out: dict[str, Any] = {}
        if field.each is not None:
            for key, item in value.items():
                if not isinstance(key, str):
                    raise self.fail(path, field, f"has a key that is not a string: {show(key)}")
                out[str(key)] = self.check(item, field.each, _join(path, key))
            return out
        fields = field.fields
        assert fields is not None
        found = 0
        for key, sub in fields.items():
            here = _join(path, key)
            if key in value:
                found += 1
                out[key] = self.check(value[key], sub, here)
            elif sub.default is REQUIRED:
                raise self.fail(here, None, "is missing")
            elif sub.default is ABSENT:
                continue
            elif sub.fields is not None:
                out[key] = self.mapping(sub.default, sub, here)
            else:
                out[key] = copy.deepcopy(sub.default)
        if found != len(value):
            for key in value:
                if not (isinstance(key, str) and key in fields):
                    here = _join(path, key)
                    raise self.error(
                        here,
                        f"unknown {self.describe(here)} (allowed keys here: "
                        f"{', '.join(sorted(fields))})" + did_you_mean(str(key), fields),
                    )
        return out

    # ------------------------------------------------------ free JSON
    def json(self, value: Any, field: Field, path: str) -> Any:
        self._budget = field.max_length if field.max_length is not None else -1
        return self._json(value, field, path, 0)

    def _json(self, value: Any, field: Field, path: str, depth: int) -> Any:
        if self._budget == 0:
            raise self.fail(
                path, field, f"makes the value hold more than {field.max_length} values"
            )
        self._budget -= 1
        if value is None or isinstance(value, bool):
            return value
        if isinstance(value, str):
            return str(value)
        if isinstance(value, np.generic):
            value = value.item()
            if not isinstance(value, bool | int | float | str):
                raise self.must(path, field, value)
            return self._json(value, field, path, depth)
        number = _as_number(value)
        if number is not None:
            if abs(number) > _FLOAT_MAX or not math.isfinite(number):
                raise self.must(path, field, value)
            return number
        if isinstance(value, os.PathLike):
            text = os.fspath(value)
            if not isinstance(text, str):
                raise self.must(path, field, value)
            return text
        if isinstance(value, np.ndarray):
            value = value.tolist()
        if isinstance(value, list | tuple | Mapping):
            if depth >= field.max_depth:
                raise self.fail(path, field, f"is nested more than {field.max_depth} levels deep")
            if isinstance(value, Mapping):
                out: dict[str, Any] = {}
                for key, item in value.items():
                    if not isinstance(key, str):
                        raise self.fail(path, field, f"has a key that is not a string: {show(key)}")
                    out[str(key)] = self._json(item, field, _join(path, key), depth + 1)
                return out
            return [self._json(v, field, f"{path}[{i}]", depth + 1) for i, v in enumerate(value)]
        raise self.must(path, field, value)


_CHECKS: dict[str, Callable[[_Walk, Any, Field, str], Any]] = {
    "number": _Walk.number,
    "integer": _Walk.integer,
    "bool": _Walk.boolean,
    "choice": _Walk.choice,
    "string": _Walk.string,
    "numbers": _Walk.listing,
    "integers": _Walk.listing,
    "strings": _Walk.listing,
    "mapping": _Walk.mapping,
    "json": _Walk.json,
}
