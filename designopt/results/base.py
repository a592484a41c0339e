"""The record base: a typed result that converts to and from the archive tree.

A record holds root ``attrs`` (kind, study, config text and resolved config, seed, the
named keys, timings) and the kind's groups as nested dicts of numpy arrays, exactly the
HDF5 layout of docs/archive.md. ``to_tree()`` gives the nested dict ``archive.write``
stores (root attrs under ``"attrs"``); ``from_tree`` reads what ``archive.read`` returns.
Two records are equal when their data and identity (kind, study, config, seed, keys)
are; timings, versions and devices are measurements and not compared.

Records are plain data: they import no study and no config model. What a record needs
beyond its arrays to print itself (its typed config, the study's units and summary
indices, the study's own summary lines) comes from a *binder* the application layer attaches
(``Record.bind``; ``designopt.app.records``): the typed config is validated once, when
first asked for.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from designopt.core.errors import ConfigError

MEASURED = ("schema_version", "versions", "jax_backend", "jax_devices", "complete",
            "compilations", "compilations_by_stage", "config_dir")  # fmt: skip
"""Root attrs that describe how a record was made, not what it holds (not compared)."""


def measured(key: str) -> bool:
    return key in MEASURED or key.endswith("_time_s") or key.endswith("_s")


def value_text(v: Any, se: Any = None, vfmt: str = ".5f", sefmt: str = ".1e",
               n: Any = None, of: Any = None) -> str:
    """``v ± se`` for print; an n/a value (NaN: a ratio over too few items) as ``n/a``,
    with ``(n of N)`` where its denominator's count is known; never a ``nan``."""
    v = float(np.asarray(v)) + 0.0  # no "-0"
    if np.isnan(v):
        if n is not None and of is not None and np.isfinite(float(np.asarray(n))):
            return f"n/a ({float(np.asarray(n)):.0f} of {float(np.asarray(of)):.0f})"
        return "n/a"
    if se is None or not np.isfinite(float(np.asarray(se))):
        return f"{v:{vfmt}}"
    return f"{v:{vfmt}} ± {float(np.asarray(se)):{sefmt}}"


def _scalar(v: Any) -> float | None:
    """A one-number value as a float (None for arrays of several numbers and non-numbers)."""
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return float(a.reshape(())) if a.size == 1 else None


def na_indices(final: Mapping[str, Any]) -> list[str]:
    """The indices of one design's results that are n/a: a value NaN beside its ``_se``
    (a ratio over too few items; every study's indices carry an SE)."""
    out = []
    for k, v in final.items():
        if k == "attrs" or k.endswith(("_se", "_n", "_of")) or k + "_se" not in final:
            continue
        x = _scalar(v)
        if x is not None and np.isnan(x):
            out.append(k)
    return out


def na_warnings(final: Mapping[str, Any], own: Sequence[str] = ()) -> list[str]:
    """``own`` (a study's warnings on one design's results) and a generic line for each
    n/a index (:func:`na_indices`) that none of them speaks of (a line about ``k``
    starts with its name): every n/a carries a ``warning:`` line, in every study.
    ``final``: the index values (a run's ``final`` group, ``eval``'s results), with
    ``<k>_n`` / ``<k>_of`` the ratio's counts where the study gives them."""
    out = list(own)
    for k in na_indices(final):
        if any(re.match(rf"{re.escape(k)}\b", w) for w in own):
            continue
        n, of = _scalar(final.get(f"{k}_n")), _scalar(final.get(f"{k}_of"))
        counts = f" ({n:.0f} of {of:.0f})" if n is not None and of is not None \
            and np.isfinite(n) and np.isfinite(of) else ""  # fmt: skip
        out.append(f"{k}: n/a{counts}: a ratio over too few items to be estimated; it has no "
                   "value and no standard error in this design")  # fmt: skip
    return out


SEARCH_LABEL = "on the search's samples"
"""How the archive and the summaries name values of the final design on the samples the
search chose it on (``best_run/final``), beside the fresh ones they quote."""


def runs_lines(runs: Mapping[str, Any] | None, names: list[str],
               units: Mapping[str, str] | None = None) -> list[str]:  # fmt: skip
    """The summary of a ``runs`` group (each run's design re-scored on one common fresh
    stream): one line per run (its objectives ± SE, whether it agrees with the reference
    run), whether the runs agree, and the flat directions; [] without one."""
    if not runs:
        return []
    at = runs.get("attrs", {})
    objs = [str(k) for k in at.get("objectives", ["f"])]
    ref = int(at.get("reference", 0))
    agree = np.asarray(runs["agree"]).astype(bool)
    z = float(at.get("z", 2.0))
    R = len(agree)
    units = units or {}
    pick = str(at.get("pick", "each run's design"))
    out = [f"runs: {pick}, re-scored on one common fresh stream ({at.get('n_samples', '-')} "
           f"samples per design), each against run {ref}:"]  # fmt: skip
    Xr = np.asarray(runs["x"], np.float64)
    for r in range(R):
        xs = ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, Xr[r], strict=False))
        vals = ", ".join(f"{k} = " + value_text(np.asarray(runs[k])[r],
                                                 np.asarray(runs[k + "_se"])[r]
                                                 if k + "_se" in runs else None)
                         for k in objs)  # fmt: skip
        tag = "reference" if r == ref else ("agrees" if agree[r] else "differs")
        out.append(f"  run {r}: {vals}  ({tag}; {xs})")
    what = ", ".join(objs)
    if agree.all():
        out.append(f"the {R} runs agree within {z:g} SE on {what}")
    else:
        why = []
        for r in np.flatnonzero(~agree):
            far = []
            for k in objs:
                v, v0 = float(np.asarray(runs[k])[r]), float(np.asarray(runs[k])[ref])
                se = np.asarray(runs.get(k + "_se", np.zeros(R)), np.float64)
                s = float(np.hypot(np.nan_to_num(se[r]), np.nan_to_num(se[ref])))
                if not np.isfinite(v - v0):
                    far.append(f"{k} (n/a)")
                elif abs(v - v0) > z * s:
                    far.append(f"{k} ({abs(v - v0) / s:.1f} SE)" if s > 0 else k)
            why.append(f"run {r} on {', '.join(far)}")
        out.append(f"the runs do not all agree within {z:g} SE of run {ref}: {'; '.join(why)}")
    flat = [str(n) for n in at.get("flat", [])]
    share = float(at.get("flat_share", 0.1))
    if int(agree.sum()) >= 2:
        X = np.asarray(runs["x"], np.float64)[agree]
        span = np.asarray(runs["span"], np.float64)
        if flat:
            parts = []
            for n in flat:
                j = names.index(n) if n in names else None
                u = "" if j is None or units.get(n) in (None, "", "-") else f" {units[n]}"
                rng = "" if j is None else f"{X[:, j].min():.4g} to {X[:, j].max():.4g}{u}, "
                parts.append(f"{n} ({rng}{100 * span[j] if j is not None else 0:.0f} % of its box)")
            out.append(f"flat directions (the agreeing designs differ by more than "
                       f"{100 * share:.0f} % of the box): {'; '.join(parts)}")  # fmt: skip
        else:
            out.append(f"no flat direction: the agreeing designs lie within {100 * share:.0f} % "
                       "of the box in every variable")  # fmt: skip
    return out


def text(v: Any) -> str:
    """A name as ``str`` (HDF5 gives bytes)."""
    return v.decode() if isinstance(v, bytes | np.bytes_) else str(v)


def names(a: Any) -> list[str]:
    """An array of names (bytes or str) as a list of ``str``."""
    return [text(v) for v in np.asarray(a).ravel()]


def _json(v: Any) -> Any:
    if isinstance(v, str) and v[:1] in "[{":
        try:
            return json.loads(v)
        except json.JSONDecodeError:
            return v
    return v


def _canon(v: Any) -> Any:
    """A comparable form: arrays as numpy, names as str, JSON attrs decoded."""
    if isinstance(v, Mapping):  # an empty attrs entry is the same as none (HDF5 adds it)
        return {k: _canon(x) for k, x in v.items() if not (k == "attrs" and not x)}
    if isinstance(v, list | tuple):
        return [_canon(x) for x in v]
    if isinstance(v, bytes | np.bytes_):
        return v.decode()
    if isinstance(v, np.ndarray) and v.dtype.kind in "SU":
        return v.astype("U")
    return _json(v)


def same(a: Any, b: Any, path: str = "") -> str | None:
    """None when ``a`` and ``b`` hold the same values (NaN equals NaN, arrays compared by
    value and shape), else the first path where they differ."""
    a, b = _canon(a), _canon(b)
    if isinstance(a, dict) or isinstance(b, dict):
        if not (isinstance(a, dict) and isinstance(b, dict)) or a.keys() != b.keys():
            return path or "/"
        for k in a:
            d = same(a[k], b[k], f"{path}/{k}")
            if d is not None:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list) and len(a) != len(b):
        return path
    x, y = np.asarray(a), np.asarray(b)
    if x.shape != y.shape:
        return path
    if x.dtype.kind in "fc" or y.dtype.kind in "fc":
        ok = np.array_equal(x.astype(np.complex128), y.astype(np.complex128), equal_nan=True)
    else:
        ok = bool(np.all(x == y)) if x.size else True
    return None if ok else path


Binder = Callable[["Record"], tuple[Any, dict[str, Any]]]
"""``binder(record) -> (typed config, hints)``: what the application layer attaches to a record."""


@dataclass(eq=False)
class Record:
    """One result: root ``attrs`` and the kind's groups (``GROUPS``, in archive order)."""

    KIND: ClassVar[str] = ""
    GROUPS: ClassVar[tuple[str, ...]] = ()
    OPTIONAL: ClassVar[tuple[str, ...]] = ()

    attrs: dict[str, Any]
    groups: dict[str, Any] = field(default_factory=dict)
    _config: Any = field(default=None, repr=False)
    _binder: Binder | None = field(default=None, repr=False)
    _bound: tuple[Any, dict[str, Any]] | None = field(default=None, repr=False)

    @classmethod
    def from_tree(cls, tree: Mapping[str, Any], config: Any = None) -> Record:  # noqa: D417
        """The record of an archive tree (``archive.read``'s nested dict, root attrs under
        ``"attrs"``); ``config``: the validated config when already at hand."""
        attrs = {k: _json(v) for k, v in dict(tree.get("attrs", {})).items()}
        missing = [g for g in cls.GROUPS if g not in tree]
        if missing:
            raise ValueError(f"a {cls.KIND or 'record'} archive needs the group(s) {missing}")
        groups = {k: v for k, v in tree.items() if k != "attrs"}
        return cls(attrs, groups, config)

    def to_tree(self) -> dict[str, Any]:
        """The nested dict ``archive.write`` stores (root attrs under ``"attrs"``)."""
        return {"attrs": dict(self.attrs), **self.groups}

    def data(self) -> dict[str, Any]:
        """The groups (the archive tree without its root attrs)."""
        return dict(self.groups)

    def __getitem__(self, group: str) -> Any:
        return self.groups[group]

    def __contains__(self, group: str) -> bool:
        return group in self.groups

    def identity(self) -> dict[str, Any]:
        return {k: v for k, v in self.attrs.items() if not measured(k)}

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Record) or type(other) is not type(self):
            return NotImplemented
        return (
            same(self.identity(), other.identity()) is None
            and same(self.groups, other.groups) is None
        )

    def differs(self, other: Record) -> str | None:
        """Where two records differ (None: equal), for test messages."""
        return same(self.identity(), other.identity(), "attrs") or same(self.groups, other.groups)

    __hash__ = None  # type: ignore[assignment]

    @property
    def kind(self) -> str:
        return str(self.attrs.get("kind", self.KIND))

    @property
    def study(self) -> str:
        return str(self.attrs.get("study", ""))

    @property
    def seed(self) -> int:
        return int(self.attrs.get("seed", 0))

    def bind(self, binder: Binder | None) -> Record:
        """Attach the application layer's ``binder(record) -> (config, hints)`` (returns self)."""
        self._binder, self._bound = binder, None
        return self

    def _context(self) -> tuple[Any, dict[str, Any]]:
        if self._bound is None:
            if self._binder is None:
                raise LookupError(f"this {self.kind or 'record'} record is bound to no config; "
                                  "read archives with designopt.load")  # fmt: skip
            self._bound = self._binder(self)
        return self._bound

    @property
    def config(self) -> Any:
        """The validated config the record was made with (given when it was made, or
        rebuilt by its binder from the archived resolved config)."""
        if self._config is None:
            self._config = self._context()[0]
        return self._config

    def hint(self, key: str, default: Any = None) -> Any:
        """What the binder says of this record beyond its data (``units``, ``summary``,
        ``extra_lines``, ``case_names``); ``default`` when unbound or its study unknown."""
        try:
            return self._context()[1].get(key, default)
        except (LookupError, ValueError, ConfigError):  # unbound, or a study or config unknown here
            return default

    def raw_config(self) -> dict[str, Any]:
        """The archived resolved config as plain data (no validation)."""
        raw = self.attrs.get("config_resolved", {})
        return json.loads(raw) if isinstance(raw, str | bytes) else dict(raw)

    @property
    def names(self) -> list[str]:
        """The design variables (the ``problem`` group's names)."""
        return names(self.groups["problem"]["names"])

    @property
    def lower(self) -> np.ndarray:
        """The design box's lower bounds (D,), in the order of ``names``."""
        return np.asarray(self.groups["problem"]["lower"], np.float64)

    @property
    def upper(self) -> np.ndarray:
        """The design box's upper bounds (D,)."""
        return np.asarray(self.groups["problem"]["upper"], np.float64)

    @property
    def info(self) -> dict[str, Any]:
        """What the study's problem says about itself (the ``problem`` group's info)."""
        return dict(self.groups["problem"].get("attrs", {}).get("info", {}))

    def keys(self) -> dict[str, Any]:
        """The named PRNG streams the record was made with (``studies.STREAMS``)."""
        from designopt.core.keys import archived_keys

        return archived_keys({"attrs": self.attrs})

    def timing_line(self) -> str:
        a = self.attrs
        return (f"wall time {float(a.get('wall_time_s', 0)):.1f} s "
                f"(compile {float(a.get('compile_time_s', 0)):.1f} s)")  # fmt: skip

    def stages_line(self, samples: int | str = "-") -> str:
        """Samples per design and the wall time split by stage (printed after a run)."""
        a = self.attrs
        by = a.get("compilations_by_stage", {})
        return (f"samples per design: {samples or '-'}; wall "
                f"{a['wall_time_s']:.1f} s = compile {a['compile_time_s']:.1f} s + run "
                f"{a['run_time_s']:.1f} s (setup {a['setup_time_s']:.1f} s, optimizer "
                f"{a['optimizer_time_s']:.1f} s, scoring/polish {a['post_time_s']:.1f} s); "
                f"{a['compilations']} XLA compilations ({by.get('setup', 0)} + "
                f"{by.get('optimizer', 0)} + {by.get('scoring_polish', 0)})")  # fmt: skip

    def summary(self) -> list[str]:
        """The lines ``designopt show`` prints after the header."""
        return [self.timing_line()]
