"""A small typed validator for the files hmlvs reads: each file's shape is declared once, and
a value of the wrong type is refused with a sentence naming the file and the key
(``cal.yaml: fixed: must be a list of parameter names, got 5``), instead of a TypeError
somewhere later or a silent misreading (``fixed: Su`` read as ``('S', 'u')``, ``f: true`` as
1.0, ``version: 1.9`` accepted).

A schema is a tree of :class:`Field` objects; :func:`validate` walks a loaded YAML/JSON
document (or, for ``.npz`` files, a mapping of numpy arrays) against it. Every file loader
(calibration, manifest board, data set, pose file, robot description) declares its schema here
or beside its reader; checks that relate several values (equal row counts, a rotation that is
orthonormal) stay with the reader.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Callable

import numpy as np

from ..errors import SchemaError  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class Field:
    """What one value must be.

    kind : "number" (finite, not a bool), "int" (integral, not a bool), "str", "bool",
        "list", "map" (keys and values checked), "struct" (known keys), "array" (a numpy
        array of ``shape`` and ``dtype``), "select" (the schema ``select(value)`` returns,
        None refusing the value), "any"
    what : how the message describes it ("a number of mm")
    items : for "list": the schema of each item; for "map": of each value
    keys : for "struct": the schema of each known key
    required : for "struct": the keys that must be there
    extra : for "struct": "error" refuses unknown keys (naming the known ones), "ignore" keeps
        them (forward-compatible files)
    length : for "list": the exact number of items
    choices : allowed values
    nullable : None (null) allowed; for an "array" of numbers, NaN entries (no value)
    check : a further test returning an error text or None
    shape : for "array": the dimensions, an int for a fixed one or a name for a free one
        (``("m", 2)``)
    dtype : for "array": "number" (integers or floats, every value finite), "int" or "id"
        (texts or integers)
    select : for "select": picks the schema of a value by its form (a mapping or a list)
    """

    kind: str
    what: str = ""
    items: "Field | None" = None
    keys: dict[str, "Field"] = field(default_factory=dict)
    required: tuple[str, ...] = ()
    extra: str = "ignore"
    length: int | None = None
    choices: tuple[Any, ...] = ()
    nullable: bool = False
    check: Callable[[Any], str | None] | None = None
    shape: tuple[int | str, ...] | None = None
    dtype: str = "number"
    select: "Callable[[Any], Field | None] | None" = None


def number(what: str = "a number", nullable: bool = False, positive: bool = False) -> Field:
    return Field("number", what, nullable=nullable,
                 check=(lambda v: None if v > 0 else "must be > 0") if positive else None)


def integer(what: str = "a whole number", nullable: bool = False, minimum: int | None = None
            ) -> Field:
    return Field("int", what, nullable=nullable,
                 check=None if minimum is None else
                 (lambda v: None if v >= minimum else f"must be >= {minimum}"))


def text(what: str = "a text", nullable: bool = False, choices: tuple[str, ...] = ()) -> Field:
    return Field("str", what, nullable=nullable, choices=choices)


def matrix(rows: int, cols: int, what: str, nullable: bool = False) -> Field:
    return Field("list", what, length=rows, nullable=nullable,
                 items=Field("list", f"a row of {cols} numbers", length=cols, items=number()))


def identifier(what: str = "an id (a text or a whole number)") -> Field:
    """An id as files write it: a text, or a whole number (read as its text)."""
    return Field("any", what, check=lambda v: None if isinstance(v, str) or (
        isinstance(v, int) and not isinstance(v, bool)) else f"must be {what}")


def non_empty(what: str) -> Callable[[Any], str | None]:
    """A check refusing an empty list."""
    return lambda v: None if len(v) else f"must hold at least one {what}"


def array(shape: tuple[int | str, ...], what: str, dtype: str = "number",
          nullable: bool = False) -> Field:
    """A numpy array (an ``.npz`` member) of ``shape`` and ``dtype`` (``nullable``: NaN
    entries allowed, infinite ones not)."""
    return Field("array", what, shape=shape, dtype=dtype, nullable=nullable)


_DTYPE_KINDS = {"number": "iuf", "int": "iu", "id": "USiu"}
_DTYPE_WHAT = {"number": "numbers", "int": "whole numbers", "id": "texts or whole numbers"}


def _shape_text(shape: tuple[int | str, ...]) -> str:
    return "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"


def _check_array(doc: Any, schema: Field) -> str | None:
    if not isinstance(doc, np.ndarray):
        return f"must be {schema.what} (an array), got {type(doc).__name__}"
    shape = schema.shape or ()
    if doc.ndim != len(shape) or any(isinstance(want, int) and got != want
                                     for got, want in zip(doc.shape, shape)):
        return f"must be {schema.what} of shape {_shape_text(shape)}, got shape {doc.shape}"
    if doc.dtype.kind not in _DTYPE_KINDS[schema.dtype]:
        return (f"must be {schema.what}: {_DTYPE_WHAT[schema.dtype]}, got an array of "
                f"{doc.dtype}")
    if schema.dtype != "number" or doc.dtype.kind != "f":
        return None
    wrong = np.isinf(doc) if schema.nullable else ~np.isfinite(doc)  # NaN: no value
    if wrong.any():
        bad = tuple(int(i) for i in np.argwhere(wrong)[0])
        at = bad[0] if len(bad) == 1 else bad
        return f"must be finite; the entry at {at} is {doc[bad]}"
    return None


def _describe(v: Any) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def validate(doc: Any, schema: Field, source: str, path: str = "") -> None:
    """Raise :class:`SchemaError` at the first value of ``doc`` that ``schema`` refuses.

    The message starts with ``source`` (the file) and the path of the value in the document
    (``points[3].pixel``); an empty ``source`` leaves the file for the caller to name.
    """
    where = ": ".join(x for x in (source, path) if x)
    where += ": " if where else ""

    def fail(msg: str) -> None:
        raise SchemaError(f"{where}{msg}")

    if schema.kind == "select" and schema.select is not None:
        chosen = schema.select(doc)
        if chosen is None:
            fail(f"must be {schema.what}, got {_describe(doc)}")
        validate(doc, chosen, source, path)
        return
    if doc is None:
        if schema.nullable or (schema.kind == "any" and schema.check is None):
            return
        fail(f"must be {schema.what or schema.kind}, got null")
    k = schema.kind
    if k == "array":
        msg = _check_array(doc, schema)
        if msg:
            fail(msg)
    elif k == "number":
        if isinstance(doc, bool) or not isinstance(doc, (int, float)):
            fail(f"must be {schema.what or 'a number'}, got {_describe(doc)}")
        if not math.isfinite(doc):
            fail(f"must be a finite number, got {doc}")
    elif k == "int":
        if isinstance(doc, bool) or not isinstance(doc, int):
            fail(f"must be {schema.what or 'a whole number'}, got {_describe(doc)}")
    elif k == "str":
        if not isinstance(doc, str):
            fail(f"must be {schema.what or 'a text'}, got {_describe(doc)}")
    elif k == "bool":
        if not isinstance(doc, bool):
            fail(f"must be true or false, got {_describe(doc)}")
    elif k == "list":
        if not isinstance(doc, list):
            fail(f"must be {schema.what or 'a list'}, got {_describe(doc)}")
        if schema.length is not None and len(doc) != schema.length:
            fail(f"must be {schema.what or 'a list'} of {schema.length} items, got {len(doc)}")
        if schema.items is not None:
            for i, v in enumerate(doc):
                validate(v, schema.items, source, f"{path}[{i}]")
    elif k == "map":
        if not isinstance(doc, dict):
            fail(f"must be {schema.what or 'a mapping'}, got {_describe(doc)}")
        if schema.items is not None:
            for key, v in doc.items():
                validate(v, schema.items, source, f"{path}.{key}" if path else str(key))
    elif k == "struct":
        if not isinstance(doc, dict):
            fail(f"must be {schema.what or 'a mapping'}, got {_describe(doc)}")
        missing = [r for r in schema.required if r not in doc]
        if missing:
            unknown = [k for k in doc if str(k) not in schema.keys]
            fail(f"lacks {', '.join(missing)}"
                 + (f" (it has the unknown key(s) {', '.join(map(repr, unknown))})"
                    if unknown and schema.extra == "error" else "")
                 + (f"; it must be {schema.what}" if schema.what else ""))
        for key, v in doc.items():
            sub = schema.keys.get(str(key))
            if sub is None:
                if schema.extra == "error":
                    fail(f"unknown key {key!r}; the keys are {', '.join(schema.keys)}")
                continue
            validate(v, sub, source, f"{path}.{key}" if path else str(key))
    if schema.choices and doc not in schema.choices:
        fail(f"must be one of {', '.join(map(str, schema.choices))}, got {_describe(doc)}")
    if schema.check is not None:
        msg = schema.check(doc)
        if msg:
            fail(f"{msg}, got {_describe(doc)}")


def header(fmt: str, version: int) -> dict[str, Field]:
    """The ``format`` and ``version`` keys every hmlvs file starts with."""
    return {"format": text(f"'{fmt}'", choices=(fmt,)),
            "version": integer(f"a whole version number <= {version}", minimum=1)}
