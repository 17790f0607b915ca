"""Generic conversion of TOML tables into frozen dataclasses with precise error messages.

Every field's type comes from its annotation; bounds and units come from ``field(metadata=...)``
built with :func:`param`. Unknown keys, wrong types and out-of-range values raise
:class:`app.errors.CaseError` naming the file and the dotted key.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from typing import Any, Literal, Union

from app.errors import CaseError

_MISSING = dataclasses.MISSING
INT_LIMIT = 2**31 - 1


def param(
    default: Any = _MISSING,
    *,
    default_factory: Any = _MISSING,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    unit: str = "",
    doc: str = "",
) -> Any:
    """A dataclass field carrying validation bounds, unit and help text."""
    meta = {"gt": gt, "ge": ge, "lt": lt, "le": le, "unit": unit, "doc": doc}
    kwargs: dict[str, Any] = {"metadata": meta}
    if default is not _MISSING:
        kwargs["default"] = default
    if default_factory is not _MISSING:
        kwargs["default_factory"] = default_factory
    return dataclasses.field(**kwargs)


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin is Literal:
        return " or ".join(repr(a) for a in typing.get_args(tp))
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp))
    if origin in (list, tuple):
        return "list"
    if origin is dict:
        return "table"
    if dataclasses.is_dataclass(tp):
        return "table"
    if tp is type(None):
        return "nothing"
    return getattr(tp, "__name__", str(tp))


def _check_bounds(value: float, meta: dict, file: str | None, key: str) -> None:
    unit = f" {meta['unit']}" if meta.get("unit") else ""
    if not math.isfinite(value):
        raise CaseError(file, key, f"must be finite, got {value}")
    for name, op, text in (
        ("gt", lambda a, b: a > b, ">"),
        ("ge", lambda a, b: a >= b, ">="),
        ("lt", lambda a, b: a < b, "<"),
        ("le", lambda a, b: a <= b, "<="),
    ):
        bound = meta.get(name)
        if bound is not None and not op(value, bound):
            raise CaseError(file, key, f"must be {text} {bound}{unit}, got {value}{unit}")


def convert(tp: Any, value: Any, file: str | None, key: str, meta: dict | None = None) -> Any:
    """Convert ``value`` to annotation ``tp`` or raise CaseError naming ``key``."""
    meta = meta or {}
    origin = typing.get_origin(tp)
    if tp is Any:
        return value
    if origin is Literal:
        allowed = typing.get_args(tp)
        if value not in allowed:
            raise CaseError(file, key, f"must be one of {', '.join(map(repr, allowed))}, got {value!r}")
        return value
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        kinds = _tagged_members(args)
        if kinds:
            return _convert_tagged(kinds, value, file, key)
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return convert(arg, value, file, key, meta)
            except CaseError as exc:
                errors.append(exc)
        if len(errors) == 1:
            raise errors[0]
        raise CaseError(file, key, f"expected {_type_name(tp)}, got {type(value).__name__} {value!r}")
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise CaseError(file, key, f"expected a table, got {type(value).__name__} {value!r}")
        return from_dict(tp, value, file, key)
    if origin is list or origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise CaseError(file, key, f"expected a list, got {type(value).__name__} {value!r}")
        args = typing.get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise CaseError(file, key, f"expected {len(args)} entries, got {len(value)}")
            return tuple(convert(a, v, file, f"{key}[{i}]", meta) for i, (a, v) in enumerate(zip(args, value)))
        item = args[0] if args else Any
        out = [convert(item, v, file, f"{key}[{i}]", meta) for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if origin is dict:
        if not isinstance(value, dict):
            raise CaseError(file, key, f"expected a table, got {type(value).__name__} {value!r}")
        _, vtype = typing.get_args(tp) or (str, Any)
        return {str(k): convert(vtype, v, file, f"{key}.{k}", meta) for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise CaseError(file, key, f"expected true or false, got {type(value).__name__} {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise CaseError(file, key, f"expected an integer, got {type(value).__name__} {value!r}")
        if abs(value) > INT_LIMIT:       # PETSc, SLEPc and numpy index with 32-bit integers
            raise CaseError(file, key, f"must be at most {INT_LIMIT} in magnitude, got {value}")
        _check_bounds(value, meta, file, key)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(file, key, f"expected a number, got {type(value).__name__} {value!r}")
        value = float(value)
        _check_bounds(value, meta, file, key)
        return value
    if tp is str:
        if not isinstance(value, str):
            raise CaseError(file, key, f"expected a string, got {type(value).__name__} {value!r}")
        return value
    raise TypeError(f"unsupported annotation {tp!r} at {key}")


def _tagged_members(args) -> dict | None:
    """{kind: dataclass} if ``args`` are dataclasses each with a one-value Literal ``kind`` field (a
    tagged union), else None."""
    kinds = {}
    for arg in args:
        if arg is type(None) or not dataclasses.is_dataclass(arg):
            return None
        tag = typing.get_type_hints(arg).get("kind")
        values = typing.get_args(tag) if typing.get_origin(tag) is Literal else ()
        if len(values) != 1:
            return None
        kinds[values[0]] = arg
    return kinds or None


def _convert_tagged(kinds: dict, value: Any, file: str | None, key: str) -> Any:
    """A table of a tagged union: its ``kind`` picks the dataclass; a key of another kind is named."""
    if isinstance(value, tuple(kinds.values())):
        return value
    if not isinstance(value, dict):
        raise CaseError(file, key, f"expected a table, got {type(value).__name__} {value!r}")
    if "kind" not in value:
        raise CaseError(file, f"{key}.kind", f"required key is missing (one of {', '.join(map(repr, kinds))})")
    kind = value["kind"]
    if kind not in kinds:
        raise CaseError(file, f"{key}.kind", f"must be one of {', '.join(map(repr, kinds))}, got {kind!r}")
    own = {f.name for f in dataclasses.fields(kinds[kind])}
    others = {f.name for cls in kinds.values() for f in dataclasses.fields(cls)}
    for name in value:
        if name not in own and name in others:
            raise CaseError(file, f"{key}.{name}", f"not a key of kind {kind!r}")
    return from_dict(kinds[kind], value, file, key)


def from_dict(cls: type, data: dict, file: str | None = None, prefix: str = "") -> Any:
    """Build dataclass ``cls`` from ``data``; unknown or missing keys raise CaseError."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    dotted = (prefix + ".") if prefix else ""
    for name in data:
        if name not in fields:
            close = [f for f in fields if f.lower().startswith(str(name)[:3].lower())]
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            known = ", ".join(sorted(fields))
            raise CaseError(file, f"{dotted}{name}", f"unknown key{hint}; known keys: {known}")
    kwargs = {}
    for name, f in fields.items():
        key = f"{dotted}{name}"
        if name in data:
            kwargs[name] = convert(hints[name], data[name], file, key, dict(f.metadata))
        elif f.default is _MISSING and f.default_factory is _MISSING:
            raise CaseError(file, key, "required key is missing")
    try:
        obj = cls(**kwargs)
    except CaseError:
        raise
    except ValueError as exc:
        raise CaseError(file, prefix or None, str(exc)) from None
    check = getattr(obj, "check", None)
    if callable(check):
        check(file, prefix)
    return obj


def refuse_repeats(items, file: str | None, key_of, what: str) -> None:
    """CaseError naming ``key_of(i)`` at the first entry ``i`` of ``items`` that repeats an earlier one
    (compared by value; unhashable entries by their repr): a list of names, facets or electrodes
    says each once."""
    first: dict = {}
    for i, item in enumerate(items):
        seen = first.setdefault(repr(item), i)
        if seen != i:
            raise CaseError(file, key_of(i), f"{what} {item!r} is listed twice (also at {key_of(seen)})")


def to_dict(obj: Any) -> Any:
    """Dataclass tree to plain TOML/JSON-able data (the 'resolved case')."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    return obj
