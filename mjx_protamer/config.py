"""Frozen-dataclass configuration loaded from YAML, validated with errors that name the field.

Every config in the project is a (nested) frozen dataclass. `load_config(Cls, path, overrides)`
reads `configs/*.yaml`, applies `a.b.c=value` overrides from the command line and builds the
dataclass, refusing unknown keys, wrong types and values outside the allowed range. Field-level
rules live next to the fields, in each dataclass's `validate()` method, which raises
`ConfigError` through `check()`; one rule holds for every field here: a float is finite (NaN or inf in
any weight, rate or threshold would silently turn training into NaN). A file over MAX_CONFIG_BYTES is refused
before it is read, and every seed field is a uint32 (`check_seed`).

YAML is read as YAML 1.2 reads numbers: `1e-4` is a float (PyYAML's YAML 1.1 resolver wants `1.0e-4`
and returns the string '1e-4' otherwise).
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Callable, Literal, TypeVar, get_args, get_origin

import yaml

T = TypeVar("T")

MAX_CONFIG_BYTES = 1 << 20  # a config file larger than this is refused before parsing (issue 42)
SEED_MAX = 2 ** 32 - 1  # every seed (config or command line) is a uint32


class ConfigError(ValueError):
    """A configuration value is missing, unknown or invalid; the message names the field."""


class _Yaml12Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2's float syntax: `1e-4`, `5E3`, `.5`, `-1.` are floats (as in JSON)."""


_Yaml12Loader.yaml_implicit_resolvers = {k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
for _first in "-+.0123456789":
    _Yaml12Loader.yaml_implicit_resolvers[_first] = [(tag, rx) for tag, rx in
                                                     _Yaml12Loader.yaml_implicit_resolvers.get(_first, [])
                                                     if tag != "tag:yaml.org,2002:float"]
_Yaml12Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                    |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                    |[-+]?\.(?:inf|Inf|INF)
                    |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+.0123456789"),
)


def yaml_load(text: str) -> Any:
    """Parse YAML text with YAML 1.2 numbers (every config file and `--set` value goes through here)."""
    return yaml.load(text, Loader=_Yaml12Loader)


def check(condition: bool, field: str, message: str) -> None:
    """Raise ConfigError for `field` unless `condition` holds."""
    if not condition:
        raise ConfigError(f"config field '{field}': {message}")


def _type_name(tp: Any) -> str:
    if get_origin(tp) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    return getattr(tp, "__name__", str(tp))


def _coerce(value: Any, tp: Any, field: str) -> Any:
    """Convert a YAML value to the annotated type, or raise a ConfigError naming the field."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        options = get_args(tp)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in options:
            if option is type(None):
                continue
            try:
                return _coerce(value, option, field)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError(f"config field '{field}': {value!r} fits none of {options}")
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed:
            raise ConfigError(
                f"config field '{field}': {value!r} is not allowed; allowed values: "
                + ", ".join(repr(a) for a in allowed)
            )
        return value
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config field '{field}': expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{field}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"config field '{field}': expected {len(args)} items, got {len(value)}")
        return tuple(_coerce(v, a, f"{field}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if isinstance(value, str) and hasattr(tp, "preset"):  # a named preset, e.g. `reward: paper`
            return tp.preset(value)
        if value is None:  # an empty section (`pretrain:` and nothing under it): the defaults
            value = {}
        if not isinstance(value, dict):
            raise ConfigError(f"config field '{field}': expected a mapping, got {value!r}")
        return _build(tp, value, prefix=f"{field}.")
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"config field '{field}': expected true or false, got {value!r}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise ConfigError(f"config field '{field}': expected an integer, got {value!r}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if not math.isfinite(value):
                raise ConfigError(f"config field '{field}': must be a finite number, got {value!r}")
            return float(value)
        raise ConfigError(f"config field '{field}': expected a number, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"config field '{field}': expected a string, got {value!r}")
    raise ConfigError(f"config field '{field}': unsupported type {_type_name(tp)}")


def _build(cls: type[T], raw: dict[str, Any], prefix: str = "") -> T:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - names)
    if unknown:
        raise ConfigError(
            f"unknown config key(s) {', '.join(prefix + k for k in unknown)}; "
            f"allowed keys under '{prefix.rstrip('.') or cls.__name__}': {', '.join(sorted(names))}"
        )
    required = [f.name for f in dataclasses.fields(cls)
                if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING and f.name not in raw]
    if required:
        raise ConfigError(f"config field(s) {', '.join(prefix + k for k in required)} missing: they have no default")
    kwargs = {k: _coerce(v, hints[k], prefix + k) for k, v in raw.items()}
    obj = cls(**kwargs)
    validate(obj, prefix)
    return obj


def validate(obj: Any, prefix: str = "") -> None:
    """Run `validate()` on a config dataclass and on its nested config dataclasses."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            validate(value, prefix + f.name + ".")
    hook = getattr(obj, "validate", None)
    if hook is not None:
        try:
            hook()
        except ConfigError as e:
            if prefix and "config field '" in str(e):
                raise ConfigError(str(e).replace("config field '", f"config field '{prefix}", 1)) from None
            raise


def _parse_scalar(text: str) -> Any:
    try:
        return yaml_load(text)
    except yaml.YAMLError:
        return text  # not YAML on its own (e.g. `a: b` quoting trouble): the field's type check names it


def apply_overrides(raw: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply `a.b=value` overrides (values parsed as YAML) to a nested dict, in place."""
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {item!r} must look like key.sub=value")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        node = raw
        for p in parts[:-1]:
            if node.get(p) is None:  # absent, or an empty section (`pretrain:` and nothing under it)
                node[p] = {}
            node = node[p]
            if not isinstance(node, dict):
                raise ConfigError(f"override {item!r}: '{p}' is not a section")
        node[parts[-1]] = _parse_scalar(text)
    return raw


def to_dict(obj: Any) -> dict[str, Any]:
    """A plain dict of a config dataclass (tuples become lists), for saving next to a run."""
    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return {f.name: conv(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, tuple):
            return [conv(x) for x in v]
        return v
    return conv(obj)


def from_dict(cls: type[T], raw: dict[str, Any] | None, section: str = "") -> T:
    """Build and validate a config dataclass from a nested dict (missing keys take defaults); `section` names
    where the dict came from in error messages (e.g. 'feedback' for the feedback section of a file)."""
    if raw is not None and not isinstance(raw, dict):
        raise ConfigError(f"config section '{section or cls.__name__}' must be a mapping (key: value lines), "
                          f"got {raw!r}")
    return _build(cls, dict(raw or {}), prefix=f"{section}." if section else "")


def check_seed(value: int, field: str) -> None:
    """A seed field's rule: a uint32 (what JAX's and NumPy's generators take without wrapping or failing)."""
    check(0 <= value <= SEED_MAX, field, f"must be a seed in 0..2^32-1, got {value}")


def check_config_size(path: str | Path, what: str = "config file") -> None:
    """Refuse a file over MAX_CONFIG_BYTES before it is read: a 64 MB YAML is parsed for minutes into gigabytes
    (a config is a few KiB, so a large one is the wrong file)."""
    size = Path(path).stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise ConfigError(f"{what} {path} is {size / 2**20:.1f} MiB; a config is a few KiB (the limit is "
                          f"{MAX_CONFIG_BYTES // 2**20} MiB): is it the right file?")


def read_raw(path: str | Path | None = None, overrides: list[str] | None = None) -> dict[str, Any]:
    """The YAML mapping in `path` ({} when None) with `a.b=value` overrides applied, not yet validated. A file
    larger than MAX_CONFIG_BYTES is refused before it is read."""
    raw: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file {path} does not exist")
        check_config_size(path)
        try:
            raw = yaml_load(path.read_text())
        except yaml.YAMLError as e:
            where = getattr(e, "problem_mark", None)
            at = f" (line {where.line + 1}, column {where.column + 1})" if where is not None else ""
            problem = getattr(e, "problem", None) or str(e).splitlines()[0]
            raise ConfigError(f"config file {path} is not valid YAML{at}: {problem}") from None
        except UnicodeDecodeError:
            raise ConfigError(f"config file {path} is not a text (UTF-8) file") from None
        if raw is None:
            raise ConfigError(f"config file {path} is empty; give at least one section, "
                              "or leave out the file to use the built-in defaults")
        if not isinstance(raw, dict):
            raise ConfigError(f"config file {path} must hold a mapping (key: value lines) at the top level, "
                              f"not a {type(raw).__name__}")
    return apply_overrides(raw, list(overrides or []))


def load_config(cls: type[T], path: str | Path | None = None, overrides: list[str] | None = None) -> T:
    """Load `cls` from a YAML file (or its defaults when path is None) with overrides applied."""
    return from_dict(cls, read_raw(path, overrides))


def shipped_config(name: str) -> Path:
    """A config file shipped with the package (`mjx_protamer/configs/<name>`, package data; `configs/` at the
    repository root links there): where a command without --config reads its built-in default, in a checkout
    and in an installed wheel alike."""
    from importlib import resources

    return Path(str(resources.files("mjx_protamer") / "configs" / name))


def check_resume_config(saved: Path, config: Any, read: Callable[[Path], Any] | None = None) -> None:
    """`--resume` continues a run only with the config it started with: refuse, naming the fields, when the config
    saved in `saved` differs from `config`. Compared as typed values, what the loader makes of the file (`read`, by
    default `load_config(type(config), saved)`): a saved file whose formatting changed, or that was written before
    a knob existed (its default keeps what the run did) or a section joined the schema, still continues."""
    try:
        before = read(saved) if read is not None else load_config(type(config), saved)
    except ConfigError as e:
        raise ConfigError(f"--resume: the config saved in {saved} no longer loads: {e}") from None
    if before != config:
        changed = _differing(to_dict(before), to_dict(config))
        raise ConfigError(f"--resume: the config differs from the one saved in {saved} in "
                          f"{', '.join(changed[:5])}{' and more' if len(changed) > 5 else ''}")


def _differing(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The dotted paths where two `to_dict` trees differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [p for k in sorted(a.keys() | b.keys())
                for p in _differing(a.get(k), b.get(k), f"{prefix}{k}.")] if a != b else []
    return [prefix.rstrip(".") or "the whole config"] if a != b else []
