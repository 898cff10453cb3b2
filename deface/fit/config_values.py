"""Settings of nested frozen config dataclasses by dotted path (``decouple.epsilon``): values read from JSON
(``check_value``) and from the command line (``parse_value``), each checked against its field's type with a
one-line error; changing, flattening and comparing configs; the settings' documentation from the fields'
docstrings. Nothing here knows the fit's schema, :mod:`deface.fit.config` (which re-exports these).

typer parses options, not ``PATH=VALUE`` strings into nested dataclasses, and pydantic is no dependency of
deface (only of the web extra's gradio), so this is our own, small and strict.
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from dataclasses import asdict, fields, is_dataclass, replace
from types import UnionType
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints


def to_dict(config: Any) -> dict:
    """A JSON-ready dict of a (nested) config."""
    return asdict(config)


def build(base: Any, data: dict, prefix: str = "") -> Any:
    """``base`` with the settings a ``to_dict`` dict gives (groups as nested dicts), every value checked against
    its field's type (lists become tuples); settings the dict leaves out keep ``base``'s values, and an unknown
    field is an error."""
    hints = field_types(type(base))
    values = {}
    for key, value in data.items():
        if key not in hints:
            raise ValueError(f"unknown config field '{prefix}{key}' (known: {', '.join(sorted(hints))})")
        hint = hints[key]
        if is_dataclass(hint):
            if not isinstance(value, dict):
                raise ValueError(f"config field '{prefix}{key}' is a group of settings, got {value!r}")
            values[key] = build(getattr(base, key), value, f"{prefix}{key}.")
        else:
            values[key] = check_value(value, hint, f"{prefix}{key}")
    return replace(base, **values)


def field_types(cls: type) -> dict[str, Any]:
    """Field name -> resolved type of a config dataclass."""
    hints = get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls)}


def check_value(value: Any, hint: Any, path: str) -> Any:
    """``value`` as a value of type ``hint`` (JSON lists -> tuples, ints -> floats), or a one-line ValueError."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return check_value(value, inner, path)
    if origin is Literal:
        if value not in args:
            raise ValueError(f"{path} must be one of {', '.join(map(str, args))}, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ValueError(f"{path} must be a list of values, got {value!r}")
        items = args[:1] * len(value) if len(args) == 2 and args[1] is Ellipsis else args
        if len(items) != len(value):
            raise ValueError(f"{path} must have {len(items)} values, got {len(value)}")
        return tuple(check_value(v, h, f"{path}[{i}]") for i, (v, h) in enumerate(zip(value, items, strict=True)))
    if hint is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{path} must be true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{path} must be an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{path} must be a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ValueError(f"{path} must be a string, got {value!r}")
        return value
    raise ValueError(f"{path}: cannot set a value of type {hint}")  # pragma: no cover - no such field today


def parse_value(text: str, hint: Any, path: str) -> Any:
    """A command-line string (``--set path=text``) as a value of type ``hint``: true/false (also yes/no,
    on/off, 1/0), numbers, none (where allowed), comma lists for tuples; one-line ValueError otherwise."""
    origin, args = get_origin(hint), get_args(hint)
    word = text.strip()
    if origin in (Union, UnionType):
        if word.lower() in ("none", "null") and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return parse_value(text, inner, path)
    if origin is tuple:
        parts = [part for part in word.split(",") if part.strip()]
        items = args[:1] * len(parts) if len(args) == 2 and args[1] is Ellipsis else args
        if not parts or len(items) != len(parts):
            count = "one or more" if len(args) == 2 and args[1] is Ellipsis else str(len(items))
            raise ValueError(f"{path} takes {count} comma-separated values, got '{text}'")
        return tuple(parse_value(part, h, f"{path}[{i}]") for i, (part, h) in enumerate(zip(parts, items, strict=True)))
    if hint is bool:
        truth = {word: True for word in ("true", "yes", "on", "1")} | {w: False for w in ("false", "no", "off", "0")}
        if word.lower() not in truth:
            raise ValueError(f"{path} must be true or false, got '{text}'")
        return truth[word.lower()]
    if hint in (int, float):
        try:
            return hint(word)
        except ValueError:
            raise ValueError(f"{path} must be {'an integer' if hint is int else 'a number'}, got '{text}'") from None
    return check_value(word, hint, path)


def field_type(cls: type, path: str) -> Any:
    """The type of the setting at dotted ``path`` of config class ``cls`` (ValueError for an unknown path)."""
    parts = path.split(".")
    for depth, part in enumerate(parts):
        hints = field_types(cls)
        if part not in hints:
            where = ".".join(parts[:depth]) or "the config"
            raise ValueError(f"unknown setting '{path}': {where} has no field '{part}' "
                             f"(known: {', '.join(sorted(hints))})")
        cls = hints[part]
        if depth < len(parts) - 1 and not is_dataclass(cls):
            raise ValueError(f"unknown setting '{path}': '{'.'.join(parts[: depth + 1])}' is a single value")
    if is_dataclass(cls):
        raise ValueError(f"'{path}' is a group of settings: set one of its fields ({', '.join(field_types(cls))})")
    return cls


def split_assignment(assignment: str) -> tuple[str, str]:
    """(path, value text) of a ``dotted.path=value`` as ``--set`` takes it; one-line ValueError otherwise."""
    path, equals, text = assignment.partition("=")
    if not equals or not path.strip():
        raise ValueError(f"--set takes PATH=VALUE (e.g. decouple.epsilon=0.12), got '{assignment}'")
    return path.strip(), text


def replace_path(config: Any, path: str, value: Any) -> Any:
    """A copy of ``config`` with the setting (or group) at dotted ``path`` replaced by ``value``."""
    return _replace_parts(config, path.split("."), value)


def _replace_parts(config: Any, parts: list[str], value: Any) -> Any:
    if not is_dataclass(config):
        raise ValueError(f"cannot set '{'.'.join(parts)}' on a non-config value")
    names = {f.name for f in fields(config)}
    if parts[0] not in names:
        raise ValueError(f"unknown config field '{parts[0]}' (known: {', '.join(sorted(names))})")
    if len(parts) == 1:
        return replace(config, **{parts[0]: value})
    return replace(config, **{parts[0]: _replace_parts(getattr(config, parts[0]), parts[1:], value)})


def flatten(config: Any, prefix: str = "") -> dict[str, Any]:
    """Every setting of a (nested) config by dotted path, in declaration order."""
    out = {}
    for f in fields(config):
        value = getattr(config, f.name)
        if is_dataclass(value):
            out.update(flatten(value, f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = value
    return out


def differences(config: Any, base: Any) -> dict[str, tuple[Any, Any]]:
    """path -> (value in ``config``, value in ``base``) for every setting where the two differ."""
    mine, theirs = flatten(config), flatten(base)
    return {path: (value, theirs[path]) for path, value in mine.items() if value != theirs[path]}


def documentation(cls: type, prefix: str = "") -> list[tuple[str, Any, str]]:
    """(dotted path, default, docstring) of every setting of a config class, from the attribute docstrings in
    the source: what ``deface fit --help`` lists."""
    docs = attribute_docs(cls)
    defaults = cls()
    out = []
    for name, hint in field_types(cls).items():
        if is_dataclass(hint):
            out += documentation(hint, f"{prefix}{name}.")
        else:
            out.append((f"{prefix}{name}", getattr(defaults, name), docs.get(name, "")))
    return out


def attribute_docs(cls: type) -> dict[str, str]:
    """Field name -> its docstring (the string literal right after the field in the class body), one line."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:], strict=False):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs
