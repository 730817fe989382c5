"""A small typed validator for the files hmlvs reads: each file's shape is declared once, and
a value of the wrong type is refused with a sentence naming the file and the key
(``cal.yaml: fixed: must be a list of parameter names, got 5``), instead of a TypeError
somewhere later or a silent misreading (``fixed: Su`` read as ``('S', 'u')``, ``f: true`` as
1.0, ``version: 1.9`` accepted).

A schema is a tree of :class:`Field` objects; :func:`validate` walks a loaded YAML/JSON
document against it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Callable


class SchemaError(ValueError):
    """A document that does not match its schema (a ``ValueError``)."""


@dataclass(frozen=True)
class Field:
    """What one value must be.

    kind : "number" (finite, not a bool), "int" (integral, not a bool), "str", "bool",
        "list", "map" (keys and values checked), "struct" (known keys), "any"
    what : how the message describes it ("a number of mm")
    items : for "list": the schema of each item; for "map": of each value
    keys : for "struct": the schema of each known key
    required : for "struct": the keys that must be there
    extra : for "struct": "error" refuses unknown keys (naming the known ones), "ignore" keeps
        them (forward-compatible files)
    length : for "list": the exact number of items
    choices : allowed values
    nullable : None (null) allowed
    check : a further test returning an error text or None
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


def _describe(v: Any) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def validate(doc: Any, schema: Field, source: str, path: str = "") -> None:
    """Raise :class:`SchemaError` at the first value of ``doc`` that ``schema`` refuses."""
    where = f"{source}: {path}: " if path else f"{source}: "

    def fail(msg: str) -> None:
        raise SchemaError(f"{where}{msg}")

    if doc is None:
        if schema.nullable or schema.kind == "any":
            return
        fail(f"must be {schema.what or schema.kind}, got null")
    k = schema.kind
    if k == "number":
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
            fail(f"lacks {', '.join(missing)}")
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
