"""The config-key reference, generated from the models the validator uses: the run
config's sections (:class:`designopt.app.config.RunConfigBase`) and every registered
study's settings model (the study registry, ``designopt.studies``). One
:class:`KeyDoc` per key: its dotted path, type, default, range and the field's
description, so the reference cannot drift from what :func:`designopt.app.config.validate`
accepts.

- :func:`keys`: the entries (all, or those under a prefix),
- :func:`markdown`: the whole reference as a Markdown page (a table per section),
- :func:`text`: the same for a terminal (``designopt config --keys [PREFIX]``).

Paths: a nested section's keys follow its own (``optimizer.constraints.method``); an
entry of a list of sections is ``[]`` (``study.arms[].port``), a value of a mapping of
sections ``*`` (``scan.vary.*.from``); a key's YAML spelling (an alias such as ``from``)
is used. A union of sections (a task region, an obstacle, a body wall, a serial chain)
lists each variant's keys, labelled by the variant's tag (``shape: box``).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import shutil
import textwrap
import types
from collections.abc import Iterator
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import annotated_types as at
import yaml
from pydantic import BaseModel, Tag
from pydantic.fields import FieldInfo

from designopt.app.config import RunConfigBase
from designopt.core.errors import ConfigError

__all__ = ["KeyDoc", "keys", "markdown", "text"]


@dataclasses.dataclass(frozen=True)
class KeyDoc:
    """One config key of the reference."""

    key: str
    """Dotted path as a config writes it (``optimizer.n_particles``, ``study.arms[].port``)."""
    type: str
    """The values it takes, in a config's words (``int``, ``list of 3 numbers``, ``section``)."""
    default: str
    """Its default as YAML (``required`` where it has none; ``—`` for a section whose
    own keys' defaults apply)."""
    range: str
    """Constraints from the field's metadata (``≥ 2``, ``one of: clip, reflect``); ``""``."""
    description: str
    """The field's description."""
    study: str | None = None
    """The study whose settings hold it (``None``: a key of the run config's own sections)."""
    table: str = ""
    """The section it belongs to (its parent path), with the variant of a union
    (``study.task.region (shape: box)``): one table of the reference per value."""
    config: str = "run"
    """Which config file holds it: ``run`` (``designopt run``, ``sweep``, ``scan``, ``eval``)
    or ``bench`` (``designopt bench``)."""


_NONE = type(None)


def _strip(tp: Any) -> tuple[Any, list[Any]]:
    """A type without its ``Annotated`` layers, and their metadata."""
    meta: list[Any] = []
    while get_origin(tp) is Annotated:
        args = get_args(tp)
        tp, meta = args[0], meta + list(args[1:])
    return tp, meta


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _members(tp: Any) -> list[Any] | None:
    """The members of a union (``None`` left out, ``Annotated`` kept), else None."""
    tp, _ = _strip(tp)
    if get_origin(tp) not in (Union, types.UnionType):
        return None
    out: list[Any] = []
    for a in get_args(tp):
        if a is _NONE:
            continue
        inner = _members(a)
        out += inner if inner is not None else [a]
    return out


def _optional(tp: Any) -> bool:
    tp, _ = _strip(tp)
    return get_origin(tp) in (Union, types.UnionType) and _NONE in get_args(tp)


def _label(member: Any) -> str:
    """A union member's variant label: its ``Tag``, else the value of its one ``Literal``
    field (``shape: box``), else its class name."""
    tp, meta = _strip(member)
    tag = next((m.tag for m in meta if isinstance(m, Tag)), None)
    if _is_model(tp):
        for name, f in tp.model_fields.items():
            ann, _ = _strip(f.annotation)
            if get_origin(ann) is Literal and len(get_args(ann)) == 1:
                return f"{f.alias or name}: {get_args(ann)[0]}"
    return tag if tag is not None else getattr(tp, "__name__", str(tp))


def _type_name(tp: Any) -> str:
    """A type in a config's words."""
    tp, _ = _strip(tp)
    members = _members(tp)
    if members is not None:
        names: list[str] = []
        for m in members:
            n = _type_name(m)
            names += [] if n in names else [n]
        out = " or ".join(names)
        return f"{out} or null" if _optional(tp) else out
    origin, args = get_origin(tp), get_args(tp)
    if tp is bool:
        return "bool"
    if tp is int:
        return "int"
    if tp is float:
        return "number"
    if tp is str:
        return "text"
    if tp is Any or tp is object:
        return "any"
    if origin is Literal:
        return "choice"
    if _is_model(tp):
        return "section"
    if origin is list:
        return f"list of {_plural(args[0])}" if args else "list"
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_plural(args[0])}"
        kinds = {_type_name(a) for a in args}
        if len(kinds) == 1:
            return f"list of {len(args)} {_plural(args[0])}"
        return "list [" + ", ".join(_type_name(a) for a in args) + "]"
    if origin is dict:
        if len(args) == 2:
            return f"mapping {{{_type_name(args[0])}: {_type_name(args[1])}}}"
        return "mapping"
    return getattr(tp, "__name__", str(tp))


def _plural(tp: Any) -> str:
    n = _type_name(tp)
    return {"number": "numbers", "int": "ints", "text": "texts", "section": "sections",
            "bool": "bools", "choice": "choices"}.get(n, n)  # fmt: skip


def _number(x: Any) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return str(x)


def _constraints(meta: list[Any]) -> list[str]:
    out: list[str] = []
    for m in meta:
        for attr, sign in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<")):
            v = getattr(m, attr, None)
            if isinstance(m, (at.Ge, at.Gt, at.Le, at.Lt)) and v is not None:
                out.append(f"{sign} {_number(v)}")
        if isinstance(m, at.MinLen) and m.min_length:
            out.append(f"at least {m.min_length} long")
        if isinstance(m, at.MaxLen) and m.max_length is not None:
            out.append(f"at most {m.max_length} long")
        if isinstance(m, at.MultipleOf):
            out.append(f"a multiple of {_number(m.multiple_of)}")
        pattern = getattr(m, "pattern", None)
        if isinstance(pattern, str):
            out.append(f"matches {pattern}")
    return out


def _range(f: FieldInfo) -> str:
    """The field's constraints: its bounds and lengths, a Literal's choices."""
    parts = _constraints(list(f.metadata))
    tp, meta = _strip(f.annotation)
    parts += _constraints(meta)
    choices: list[Any] = []
    for m in _members(tp) or [tp]:
        m, _ = _strip(m)
        if get_origin(m) is Literal:
            choices += [c for c in get_args(m) if c not in choices]
    if choices:
        parts.append("one of: " + ", ".join(_yaml(c) for c in choices))
    return "; ".join(parts)


def _yaml(v: Any) -> str:
    """A value as a config writes it (flow-style YAML, one line)."""
    if isinstance(v, BaseModel):
        v = v.model_dump(mode="json", by_alias=True)
    if isinstance(v, float):
        return _number(v) if math.isfinite(v) else str(v)
    if isinstance(v, tuple):
        v = list(v)
    try:
        out = yaml.safe_dump(v, default_flow_style=True, sort_keys=False, width=10**6)
    except yaml.YAMLError:
        return str(v)
    return out.strip().removesuffix("...").strip()


def _default(f: FieldInfo) -> str:
    if f.is_required():
        return "required"
    v = f.get_default(call_default_factory=True)
    if isinstance(v, BaseModel):  # its keys' defaults say it, unless some key has none
        required = any(g.is_required() for g in type(v).model_fields.values())
        return _yaml(v) if required else "—"
    return "null" if v is None else _yaml(v)


def _models(tp: Any) -> tuple[str, list[tuple[str | None, type[BaseModel]]]]:
    """How a field's type holds sections: (the path suffix, [(variant label, model)]);
    ``("", [])`` for a field without sections."""
    tp, _ = _strip(tp)
    members = _members(tp)
    if members is not None:
        found = [(m, _strip(m)[0]) for m in members]
        models = [(_label(m), t) for m, t in found if _is_model(t)]
        if models:
            return "", models if len(models) > 1 else [(None, models[0][1])]
        for _, t in found:  # e.g. list[float] | Range, list[Section] | None
            suffix, inner = _models(t)
            if inner:
                return suffix, inner
        return "", []
    if _is_model(tp):
        return "", [(None, tp)]
    origin, args = get_origin(tp), get_args(tp)
    if origin in (list, tuple) and args:
        suffix, inner = _models(args[0])
        return ("[]" + suffix, inner) if inner else ("", [])
    if origin is dict and len(args) == 2:
        suffix, inner = _models(args[1])
        return (".*" + suffix, inner) if inner else ("", [])
    return "", []


def _walk(model: type[BaseModel], prefix: str, table: str, study: str | None,
          skip: tuple[str, ...] = ()) -> Iterator[KeyDoc]:  # fmt: skip
    """Every key of ``model`` under ``prefix``, depth first (a section's own keys before
    its sub-sections')."""
    nested: list[tuple[str, list[tuple[str | None, type[BaseModel]]]]] = []
    for name, f in model.model_fields.items():
        if name in skip:
            continue
        key = f"{prefix}{_yaml_name(name, f)}"
        yield KeyDoc(key=key, type=_type_name(f.annotation), default=_default(f),
                     range=_range(f), description=" ".join((f.description or "").split()),
                     study=study, table=table)  # fmt: skip
        suffix, inner = _models(f.annotation)
        if inner:
            nested.append((key + suffix, inner))
    for path, inner in nested:
        for label, sub in inner:
            yield from _walk(sub, path + ".", f"{path} ({label})" if label else path, study)


def _yaml_name(name: str, f: FieldInfo) -> str:
    """The key as a config spells it: ``json_schema_extra["config_key"]`` where a
    validator moves it (``objective.pareto``), else its alias, else its name."""
    extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
    if isinstance(extra.get("config_key"), str):
        return str(extra["config_key"])
    alias = f.validation_alias if isinstance(f.validation_alias, str) else f.alias
    return alias or name


def _studies() -> list[tuple[str, type[BaseModel]]]:
    from designopt.studies import STUDIES

    return [(name, s.settings) for name, s in sorted(STUDIES.items())]


def _all() -> list[KeyDoc]:
    from designopt.app.config import run_config_model
    from designopt.bench.suite import BenchConfig

    out = list(_walk(RunConfigBase, "", "", None))
    study = run_config_model().model_fields["study"]
    out.append(KeyDoc(key="study", type="section", default="required", range="",
                      description=" ".join((study.description or "").split())))  # fmt: skip
    for name, settings in _studies():
        out += _walk(settings, "study.", "study", name)
    out += [dataclasses.replace(e, config="bench") for e in _walk(BenchConfig, "", "", None)]
    return out


def _select(entries: list[KeyDoc], prefix: str | None) -> list[KeyDoc]:
    """The entries under ``prefix``: a dotted key and every key below it (``[]`` and
    ``*`` may be left out: ``study.arms.port``), or a study's name (its settings' keys).
    ConfigError naming the prefix, with close matches, when nothing is under it."""
    if prefix is None or prefix == "":
        return entries
    studies = {e.study for e in entries if e.study}
    if prefix in studies:
        return [e for e in entries if e.study == prefix]
    want = prefix.strip().rstrip(".")

    def plain(k: str) -> str:
        return k.replace("[]", "").replace(".*", "")

    picked = [e for e in entries if any(k == want or k.startswith(want + ".")
                                        for k in (e.key, plain(e.key)))]  # fmt: skip
    if picked:
        return picked
    names = sorted({e.key for e in entries} | {plain(e.key) for e in entries} | studies)
    close = difflib.get_close_matches(want, names, n=4, cutoff=0.6)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise ConfigError(f"config key '{prefix}': no such key or section{hint} "
                      "(`designopt config --keys` lists every key)")  # fmt: skip


def keys(prefix: str | None = None) -> list[KeyDoc]:
    """Every config key the validator accepts, as :class:`KeyDoc` entries in the
    models' order: the run config's sections, then each registered study's settings
    (``study.…``, with :attr:`KeyDoc.study` naming the study). ``prefix`` keeps a key
    and the keys below it (``optimizer``, ``study.task.ik``) or one study's keys (its
    name, ``serial``); an unknown prefix raises ConfigError naming it, with close
    matches."""
    return _select(_all(), prefix)


def _cell(s: str) -> str:
    return s.replace("|", "\\|").replace("\n", " ") if s else ""


def _code(s: str) -> str:
    return f"`{s}`" if s else ""


def _groups(entries: list[KeyDoc]) -> Iterator[tuple[KeyDoc, list[KeyDoc]]]:
    """(the first entry, the entries) of each table, in order of first appearance."""
    order: dict[tuple[str, str | None, str], list[KeyDoc]] = {}
    for e in entries:
        order.setdefault((e.config, e.study, e.table), []).append(e)
    for es in order.values():
        yield es[0], es


def _heading(e: KeyDoc) -> tuple[str, str]:
    """(the reference's section of an entry, its Markdown title)."""
    if e.config == "bench":
        return "bench", "Benchmark configs (`designopt bench`)"
    if e.study is not None:
        return f"study {e.study}", f"Study `{e.study}` (`study.name: {e.study}`)"
    top = e.table.split(".")[0].split(" ")[0]
    return (top, f"`{top}`") if top else ("", "Top-level keys")


def markdown() -> str:
    """The whole reference as Markdown: one section for the run config's top-level keys,
    one per top-level section (``optimizer``, ``refine``, ...), one per registered study
    and one for the benchmark config; a table per section or variant (key | type |
    default | range | description)."""
    lines = [
        "# Config key reference",
        "",
        "This page is generated from the schema at build time (the pydantic models the "
        "config validator uses; `designopt config --keys` prints the same for the installed "
        "version): every key a config accepts, with its type, default, range and "
        "description. Unknown keys are errors. In a key, `[]` stands for an entry of a "
        "list and `*` for a name of your choice; a section with variants (a task region, "
        "an obstacle, a body wall, a chain) has one table per variant.",
        "",
    ]
    head = "| key | type | default | range | description |\n|---|---|---|---|---|"
    current: str | None = None
    for first, es in _groups(_all()):
        section, title = _heading(first)
        if section != current:
            current = section
            lines += [f"## {title}", ""]
            if first.study is not None:
                doc = next(m for n, m in _studies() if n == first.study).__doc__ or ""
                if doc.strip():
                    lines += [" ".join(doc.split("\n\n")[0].split()), ""]
        if first.table not in ("", "study", section):
            lines += [f"### `{first.table}`", ""]
        lines.append(head)
        for e in es:
            default = e.default if e.default in ("—", "required") else _code(_cell(e.default))
            lines.append(f"| {_code(e.key)} | {_cell(e.type)} | {default} | "
                         f"{_cell(e.range)} | {_cell(e.description)} |")  # fmt: skip
        lines.append("")
    return "\n".join(lines)


def text(prefix: str | None = None, width: int | None = None) -> str:
    """The reference (or the keys under ``prefix``, as :func:`keys` selects them) for a
    terminal: per key a line ``key  type  default …  (range)`` and its description
    wrapped below it, indented; a line names each study, variant and the benchmark
    config before their keys. ``width``: the line width (default: the terminal's, 60 to
    100)."""
    entries = keys(prefix)
    if width is None:
        width = min(max(shutil.get_terminal_size((100, 24)).columns, 60), 100)
    out: list[str] = []
    section: str | None = None
    for first, es in _groups(entries):
        name, title = _heading(first)
        if first.config == "bench" or first.study is not None:
            if name != section:
                out += ([""] if out else []) + [title.replace("`", "") + ":"]
        section = name
        if " (" in first.table:
            out.append(f"  {first.table}:")
        for e in es:
            head = f"{e.key}  {e.type}  default {e.default}"
            if e.range:
                head += f"  ({e.range})"
            out += textwrap.wrap(head, width, subsequent_indent="      ",
                                 break_on_hyphens=False)  # fmt: skip
            out += textwrap.wrap(e.description or "(no description)", width,
                                 initial_indent="    ", subsequent_indent="    ",
                                 break_on_hyphens=False)  # fmt: skip
    return "\n".join(out) + "\n"
