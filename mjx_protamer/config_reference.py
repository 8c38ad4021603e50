"""docs/config.md, written from the config dataclasses: every section, every knob, its default, its meaning and
which shipped config sets it.

A knob's meaning is its field's comment in the source (the comment lines right above the field and the one at the
end of its line), so the page is written where the knob is and cannot drift from it: the test
(tests/reliability/test_config_reference.py) fails when docs/config.md differs from what `render()` writes, or
when a field has no comment. Regenerate the page with `python -m mjx_protamer.config_reference`.
"""

from __future__ import annotations

import ast
import dataclasses
import fnmatch
import inspect
import io
import json
import textwrap
import tokenize
import typing
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = Path(__file__).resolve().parent / "configs"  # the shipped files (package data; configs/ links here)
PAGE = ROOT / "docs" / "config.md"


def schemas() -> list[tuple[str, type, tuple[str, ...], str]]:
    """(name, top-level dataclass, the shipped files it reads, the commands that read it)."""
    from audio_frontend.config import VoiceConfig
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.experiments.table2 import Table2Config
    from mjx_protamer.human.feedback_config import FeedbackRunConfig

    return [
        ("pretrain", PretrainConfig, ("pretrain.yaml", "paper_single_env.yaml"),
         "`protamer pretrain --config`, `--set`; a run's saved `config.yaml`"),
        ("feedback", FeedbackRunConfig, ("feedback_*.yaml",),
         "`protamer pretrain --feedback-config`, `protamer finetune --config`"),
        ("table2", Table2Config, ("table2*.yaml",), "`protamer reproduce table2 --config`, `reproduce rescore`"),
        ("voice", VoiceConfig, ("voice.yaml",), "`protamer listen`, `calibrate`, `finetune --voice-config`"),
    ]


def field_comments(cls: type) -> dict[str, str]:
    """Each field's comment: the comment lines right above it and those on its own lines, joined; an inherited
    field's where its class declares it."""
    out: dict[str, str] = {}
    for base in reversed(cls.__mro__):
        if dataclasses.is_dataclass(base) and "__dataclass_fields__" in vars(base):
            out.update(_own_field_comments(base))
    return out


def _own_field_comments(cls: type) -> dict[str, str]:
    src = textwrap.dedent(inspect.getsource(cls))
    comments: dict[int, tuple[str, bool]] = {}  # line -> (text, whole line)
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = (tok.string.lstrip("#").strip(), tok.line.strip().startswith("#"))
    out = {}
    for node in ast.parse(src).body[0].body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            above, line = [], node.lineno - 1
            while line in comments and comments[line][1]:
                above.insert(0, comments[line][0])
                line -= 1
            own = [comments[n][0] for n in range(node.lineno, node.end_lineno + 1) if n in comments]
            out[node.target.id] = " ".join(above + own)
    return out


def section_type(tp) -> type | None:
    """The dataclass a field holds (itself, in a tuple or behind None), or None for a plain value."""
    if dataclasses.is_dataclass(tp):
        return tp
    return next((t for t in (section_type(a) for a in typing.get_args(tp) if a is not Ellipsis) if t), None)


def walk(cls: type, path: str, seen: dict[type, list[str]]) -> None:
    """Every section class under `cls`, in order, with the paths it is found at."""
    seen.setdefault(cls, []).append(path)
    for f in dataclasses.fields(cls):
        sub = section_type(typing.get_type_hints(cls)[f.name])
        if sub is not None:
            walk(sub, f"{path}.{f.name}" if path else f.name, seen)


def shipped_files() -> dict[str, type]:
    """Each file in configs/ and the schema it is read as; a file no schema claims is an error."""
    files = {}
    for p in sorted(CONFIGS.glob("*.yaml")):
        owners = [cls for _, cls, globs, _ in schemas() if any(fnmatch.fnmatch(p.name, g) for g in globs)]
        if len(owners) != 1:
            raise ValueError(f"configs/{p.name}: no schema in config_reference.schemas() claims it")
        files[p.name] = owners[0]
    return files


def set_by(files: dict[str, type]) -> dict[tuple[type, str], list[str]]:
    """(section class, field) -> the shipped files that set it."""
    from mjx_protamer.config import yaml_load

    found: dict[tuple[type, str], list[str]] = {}

    def mark(cls, raw, name):
        if not isinstance(raw, dict):  # a preset name (`reward: paper`) or an empty section
            return
        hints = typing.get_type_hints(cls)
        for key, value in raw.items():
            sub = section_type(hints[key])
            if sub is not None and isinstance(value, (dict, list)):
                for item in value if isinstance(value, list) else [value]:
                    mark(sub, item, name)
            else:
                found.setdefault((cls, key), []).append(name)

    for name, cls in files.items():
        mark(cls, yaml_load((CONFIGS / name).read_text()), name)
    return found


def _value(v) -> str:
    from mjx_protamer.config import to_dict

    if dataclasses.is_dataclass(v):
        v = to_dict(v)
    elif isinstance(v, tuple) and v and dataclasses.is_dataclass(v[0]):
        v = [to_dict(x) for x in v]
    return json.dumps(v if not isinstance(v, tuple) else list(v))


def _absent(f: dataclasses.Field, sub: type) -> str:
    """What an absent section is, where it is not the section's own defaults (a key missing under a present
    section takes the class default of the key, in the section's table)."""
    from mjx_protamer.config import to_dict

    if f.default_factory is dataclasses.MISSING and f.default is dataclasses.MISSING:
        return ""
    made = to_dict(f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default)

    def diff(a, b):
        return {k: (diff(a[k], b[k]) if isinstance(a[k], dict) else a[k]) for k in a if a[k] != b[k]}

    changed = diff(made, to_dict(sub()))
    return f"; when the section is absent: `{json.dumps(changed)}`" if changed else ""


def _files_cell(names: list[str], files: dict[str, type]) -> str:
    """The files that set a key, a schema's whole set as `all <schema>`; "-" for none."""
    parts = []
    for schema, cls, _, _ in schemas():
        mine = [n for n, c in files.items() if c is cls]
        setting = [n for n in mine if n in names]
        if setting and len(setting) == len(mine) and len(mine) > 1:
            parts.append(f"all {schema}")
        else:
            parts += [n.removesuffix(".yaml") for n in setting]
    return ", ".join(parts) or "-"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _anchor(cls: type) -> str:
    return cls.__name__.lower()


def render() -> str:
    files = shipped_files()
    sets = set_by(files)
    sections: dict[type, list[str]] = {}
    for name, cls, _, _ in schemas():
        walk(cls, "", sections)
    lines = [
        "# Configuration reference",
        "",
        "Every knob of every config, with its default, its meaning and the shipped files in `configs/` that set it",
        "(\"-\": none does; the default is what runs). Generated from the dataclasses and their field comments by",
        "`python -m mjx_protamer.config_reference`; do not edit by hand (tests/reliability/test_config_reference.py",
        "holds the page equal to the code). How a file is read and checked: [reliability.md](reliability.md#configs-mjx_protamerconfigpy).",
        "A key is set in a YAML file under its section, or on the command line with `--set section.key=value`.",
        "",
        "## Files",
        "",
        "| schema | top-level class | shipped files | read by |",
        "| --- | --- | --- | --- |",
    ]
    for name, cls, _, readers in schemas():
        shipped = ", ".join(f"`configs/{f}`" for f, c in files.items() if c is cls) or "-"
        lines.append(f"| {name} | [`{cls.__name__}`](#{_anchor(cls)}) | {shipped} | {readers} |")
    for cls, paths in sections.items():
        lines += ["", f"## {cls.__name__}", ""]
        where = []
        for name, root, _, _ in schemas():
            here = [p for p in _paths_under(root, cls) if p is not None]
            if here:
                where.append(f"{name}: " + ", ".join(f"`{p}`" if p else "the top level" for p in here))
        lines.append(f"`{cls.__module__}.{cls.__name__}`; in " + "; ".join(where) + ".")
        doc = inspect.getdoc(cls)
        if doc and not doc.startswith(cls.__name__ + "("):  # dataclasses make up a signature when there is none
            lines += ["", doc.split("\n\n")[0].replace("\n", " ")]
        if hasattr(cls, "preset"):
            lines += ["", f"A preset name may stand for the whole section: {', '.join(cls.PRESETS)}."]
        lines += ["", "| key | default | set in | meaning |", "| --- | --- | --- | --- |"]
        comments = field_comments(cls)
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            sub = section_type(hints[f.name])
            if f.default is not dataclasses.MISSING:
                default = f"`{_value(f.default)}`"
            elif f.default_factory is not dataclasses.MISSING:
                default = f"`{_value(f.default_factory())}`"
            else:
                default = "(required)"
            if sub is not None:
                default = f"[`{sub.__name__}`](#{_anchor(sub)})" + (
                    f": `{_value(f.default)}`" if isinstance(f.default, tuple) else _absent(f, sub))
            shipped = _files_cell(sets.get((cls, f.name), []), files)
            if sub is not None and shipped == "-":
                shipped = ""  # its keys say where they are set
            lines.append(f"| `{f.name}` | {_cell(default)} | {shipped} | {_cell(comments.get(f.name, ''))} |")
    return "\n".join(lines) + "\n"


def _paths_under(root: type, cls: type) -> list[str]:
    seen: dict[type, list[str]] = {}
    walk(root, "", seen)
    return seen.get(cls, [])


def main(argv: list[str] | None = None) -> None:
    import argparse

    argparse.ArgumentParser(prog="python -m mjx_protamer.config_reference",
                            description=f"Write {PAGE.relative_to(ROOT)} from the config dataclasses' fields and "
                            "comments.").parse_args(argv)
    PAGE.write_text(render())
    print(f"wrote {PAGE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
