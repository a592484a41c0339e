"""Records of runs: one optimisation (``RunRecord``), a sweep of them (``SweepRecord``),
an interrupted run's checkpoint (``CheckpointRecord``) and a study whose run is a replay
(``ReplayRecord``). Groups and attrs: docs/archive.md."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from designopt.results.base import SEARCH_LABEL, Record, runs_lines, value_text
from designopt.results.verdict import lines as verdict_lines


def _unit(u: str | None) -> str:
    """`` u`` for a unit worth printing ("" for none or dimensionless "-")."""
    return "" if u in (None, "", "-") else f" {u}"


def _pm(name: str, v: float, se: float | None, fin: Any = None, unit: str | None = None) -> str:
    if np.isnan(v):  # n/a: a ratio over too few items
        fin = {} if fin is None else fin
        return f"  {name:<5} = " + value_text(v, se, n=fin.get(name + "_n"),
                                               of=fin.get(name + "_of"))  # fmt: skip
    v = v + 0.0  # no "-0"
    if se is None:
        return f"  {name:<5} = {v:.5g}{_unit(unit)}"
    rel = f" ({100 * se / abs(v):.2f} %)" if abs(v) > se else ""  # no ratio on a tiny value
    return f"  {name:<5} = {v:.5f} ± {se:.1e}{_unit(unit)}{rel}"


def targets_csv_text(g: Mapping[str, Any]) -> str:
    """The ``targets`` group (a design at every target) as CSV: one row per arm and
    target, each column headed with its unit: arm (from 0, as ``reach_<k>``), target
    (from 0, its row in the archive's ``target_p``), x, y, z, reached (0/1), the joints
    (degrees for a revolute joint; the archive keeps radians), inv_k, clearance, the last three empty
    where the target is not reached (with arms of several robots, a ``robot`` column after
    ``arm``, the joints q1 … qn of the longest chain, empty past an arm's own), then the arm's own values on every row (the study's
    ``arm_values`` with their ``arm_columns`` headings: the serial study's port on the
    body wall and base pose); full float precision (``repr``). A front's group (every
    array with a leading design axis) gives every design's rows, a first column
    ``design`` (its row in the archive's ``front/x``, from 0)."""
    at = g.get("attrs", {})
    u = str(at.get("length_unit", ""))
    names = [str(n) for n in at.get("joints", [])]
    q_units = [str(x) for x in at.get("q_units", [])]
    p = np.asarray(g["target_p"], np.float64)
    ok = np.asarray(g["success"])
    q = np.asarray(g["q"], np.float64)
    front = ok.ndim == 3
    if not front:  # one design: a design axis of one, not written
        ok, q = ok[None], q[None]
    P, A, N = ok.shape
    names = names or [f"q{i + 1}" for i in range(q.shape[-1])]
    q_units = q_units or ["rad"] * q.shape[-1]
    robots = [str(r) for r in at.get("arm_robots", [])]  # arms of several robots
    head = ["design"] if front else []
    head += ["arm"] + (["robot"] if robots else []) + ["target", f"x [{u}]", f"y [{u}]",
                                                       f"z [{u}]", "reached"]  # fmt: skip
    head += [f"{n} [{'deg' if qu == 'rad' else qu}]" for n, qu in zip(names, q_units, strict=True)]
    q = np.where(np.asarray(q_units) == "rad", np.rad2deg(q), q)  # ("mixed": as archived)
    extra = [(k, f"{k} [{u}]" if k == "clearance" else k) for k in ("inv_k", "clearance") if k in g]
    head += [h for _, h in extra]
    ev = {k: np.asarray(g[k], np.float64) if front else np.asarray(g[k], np.float64)[None]
          for k, _ in extra}  # fmt: skip
    av = None
    if "arm_values" in g:
        av = np.asarray(g["arm_values"], np.float64)
        av = av if front else av[None]
        head += [str(c) for c in at.get("arm_columns", [])] or \
            [f"arm_value_{j}" for j in range(av.shape[-1])]  # fmt: skip
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for d in range(P):
        for a in range(A):
            own = [] if av is None else [repr(float(c)) for c in av[d, a]]
            for i in range(N):
                hit = bool(ok[d, a, i])  # an unreached target has no solution: empty cells
                w.writerow([*([d] if front else []), a, *([robots[a]] if robots else []), i,
                            *(repr(float(c)) for c in p[i]), int(hit),
                            *(repr(float(c)) if hit and np.isfinite(c) else "" for c in q[d, a, i]),
                            *(repr(float(ev[k][d, a, i])) if hit else "" for k, _ in extra),
                            *own])  # fmt: skip
    return buf.getvalue()


@dataclass(eq=False)
class RunRecord(Record):
    """One optimisation: groups ``optimizer`` (history (runs, T+1), best_f, best_x,
    converged_at, history_x), ``best_run`` (every index along the best run),
    ``problem`` (names, box, info), ``final`` (the final design with every index ± SE,
    re-scored on fresh samples; its values on the search's samples in ``best_run/final``)
    and, after a polish, ``refine``; with ``optimizer.n_runs`` ≥ 2, ``runs`` (each run's
    best design on one common fresh stream, and whether the runs agree)."""

    KIND: ClassVar[str] = "run"
    GROUPS: ClassVar[tuple[str, ...]] = ("optimizer", "best_run", "problem", "final")

    @property
    def x(self) -> dict[str, float]:
        """The final design: variable → value."""
        xf = np.asarray(self.groups["final"]["x"], np.float64)
        return dict(zip(self.names, xf.tolist(), strict=True))

    @property
    def f(self) -> float:
        return float(self.groups["final"]["f"])

    @property
    def indices(self) -> dict[str, tuple[float, float | None]]:
        """Every index of the final design: name → (value, standard error or None)."""
        fin = self.groups["final"]
        out = {}
        for k, v in fin.items():
            if k in ("x", "attrs") or k.endswith("_se") or np.ndim(v):
                continue  # the design, and what the study places in the world (placement)
            se = fin.get(k + "_se")
            out[k] = (float(np.asarray(v)), None if se is None else float(np.asarray(se)))
        return out

    @property
    def history(self) -> np.ndarray:
        """Best f so far per run and iteration (runs, T+1)."""
        return np.asarray(self.groups["optimizer"]["history"])

    @property
    def fidelity(self) -> dict[str, Any]:
        """The study settings the search scored with instead of the study's own
        (``optimizer.fidelity``; {} when it used the study's): the best run's values and
        ``best_run/final`` are at these settings, ``final`` at the study's."""
        return dict(self.config.optimizer.fidelity)

    @property
    def history_x(self) -> np.ndarray:
        """Each run's best design per iteration (runs, T+1, D)."""
        return np.asarray(self.groups["optimizer"]["history_x"])

    @property
    def best_run(self) -> dict[str, np.ndarray]:
        """Every index (and ``_se``) along the best run, with ``iteration`` (T+1,)."""
        return {k: np.asarray(v) for k, v in self.groups["best_run"].items()
                if k != "attrs" and not isinstance(v, Mapping)}  # fmt: skip

    @property
    def search(self) -> dict[str, Any]:
        """The final design's values on the search's own samples (``best_run/final``:
        f and every index with ``_se``), biased by the search's choice among designs
        scored on them; {} in archives written before the final re-scoring."""
        g = self.groups["best_run"].get("final", {})
        return {k: v for k, v in g.items() if k != "attrs"}

    @property
    def fresh(self) -> bool:
        """Whether ``final`` holds values on a fresh sample stream (``final`` attrs
        ``samples``), not the search's own."""
        return str(self.groups["final"].get("attrs", {}).get("samples", "")) == "fresh"

    @property
    def n_samples_search(self) -> int:
        """Samples per design in the search (the final design's re-scoring: ``n_samples_used``)."""
        at = self.groups["final"].get("attrs", {})
        return int(at.get("n_samples_search", at.get("n_samples_used", 0)))

    def final_stream(self) -> tuple[Any, dict[str, Any]]:
        """(study settings, named keys) of the samples ``final/`` is on, for drawing the
        final design where its quoted values were measured (a task's targets): the fresh
        ``final`` stream with ``final.n_samples`` (from the binder); a run written before
        the re-scoring: its own (``config.study``, ``keys()``)."""
        made = self.hint("final_stream")
        return made() if made is not None else (self.config.study, self.keys())

    @property
    def runs(self) -> dict[str, Any] | None:
        """Each run's best design re-scored on one common fresh stream (``runs``: ``x``
        (R, D), every index ± SE (R,), ``agree`` (R,), ``span`` (D,), attrs) with
        ``optimizer.n_runs`` ≥ 2; None otherwise."""
        return self.groups.get("runs")

    @property
    def final(self) -> dict[str, Any]:
        """The final design's values: ``x`` (D,), f and every index with ``_se``."""
        return {k: v for k, v in self.groups["final"].items() if k != "attrs"}

    @property
    def best_run_index(self) -> int:
        return int(self.groups["best_run"]["attrs"]["run_index"])

    @property
    def stage(self) -> str:
        return str(self.groups["final"]["attrs"]["stage"])

    @property
    def warnings(self) -> list[str]:
        """Where the final design's results are far from what was asked (a task region
        barely reached, an index constraint missed); empty when none."""
        w = self.groups["final"].get("attrs", {}).get("warnings", [])
        return [w] if isinstance(w, str) else [str(x) for x in w]

    @property
    def target_lines(self) -> list[str]:
        """The study's lines on the final design's targets (the ``targets`` group's attr
        ``lines``: a task's IK coverage); empty without them."""
        tl = self.groups.get("targets", {}).get("attrs", {}).get("lines", [])
        return [tl] if isinstance(tl, str) else [str(x) for x in tl]

    @property
    def n_samples_used(self) -> int:
        return int(self.groups["final"]["attrs"].get("n_samples_used", 0))

    def design_lines(self) -> list[str]:
        """The run summary: the best design, f, what the polish gained, the study's
        sub-objectives with ± SE, feasibility, the study's own lines."""
        cfg = self.config
        units = self.hint("units", {})
        fin, opt, best = self.groups["final"], self.groups["optimizer"], self.best_run_index
        lines = [f"best design (run {best} of {cfg.optimizer.n_runs}; final stage: {self.stage}):"]
        lines += [f"  {n} = {v:9.4f} {units.get(n, '')}".rstrip() for n, v in self.x.items()]
        srch = self.search
        if self.fresh and "f" in srch:
            se = fin.get("f_se")
            lines.append(f"  f     = {value_text(self.f, se)}   (fresh samples, "
                         f"{self.n_samples_used} per design; {SEARCH_LABEL}"
                         f"{' with optimizer.fidelity' if cfg.optimizer.fidelity else ''} "
                         f"{value_text(srch['f'], srch.get('f_se'))}; {cfg.optimizer.name} "
                         f"converged at iteration {opt['converged_at'][best]})")  # fmt: skip
        else:
            lines.append(f"  f     = {self.f:.5f}   ({cfg.optimizer.name} {opt['best_f'][best]:.5f}, "
                         f"converged at iteration {opt['converged_at'][best]})")  # fmt: skip
        if "refine" in self.groups:
            r = self.groups["refine"]
            at = r["attrs"]
            n = (f"{at['steps']} steps" if "steps" in at
                 else f"{np.shape(r['history'])[-1] - 1} iterations")  # fmt: skip
            lines.append(f"  polish ({at['method']}, {n}, {SEARCH_LABEL}) "
                         f"gained Δf = {np.max(r['gain']):.2e}")  # fmt: skip
        for k in self.hint("summary", ()):
            se = fin.get(k + "_se")
            lines.append(_pm(k, float(fin[k]), None if se is None else float(se), fin,
                             units.get(k)))  # fmt: skip
        if "violation" in fin:
            v = float(fin["violation"])
            ok = "feasible" if v <= 0 else f"violated by {v:.3g} (no feasible design found)"
            lines.append(f"  constraints: {ok}")
        lines += list(self.hint("extra_lines", []))
        lines += [f"  {ln}" for ln in self.target_lines]
        lines += [f"  {ln}" for ln in runs_lines(self.runs, self.names, units)]
        lines += [f"  {ln}" for ln in verdict_lines(self.groups.get("verdict"), self.names, units)]
        lines += [f"  warning: {w}" for w in self.warnings]
        return lines

    def run_line(self) -> str:
        """The Monte-Carlo samples behind each index (printed after a run; the command
        line's last line splits the wall time, ``designopt.cli.commands.wall_line``)."""
        n = self.n_samples_used
        if self.fresh:
            return (f"samples per design: {self.n_samples_search or '-'} in the search, "
                    f"{n or '-'} fresh for the final values")  # fmt: skip
        return f"samples per design: {n or '-'}"

    def summary(self) -> list[str]:
        """What ``designopt show`` prints: the final design, f and the study's indices."""
        fin = self.groups["final"]
        lines = [self.timing_line(),
                 "final design: " + ", ".join(f"{n} = {v:.4f}" for n, v in self.x.items())]  # fmt: skip
        subs = [k for k in fin if k + "_se" in fin and k != "f"][:6]
        summary = self.hint("summary")  # None: a study unknown to this process
        if summary is not None:
            subs = [k for k in summary if k + "_se" in fin]
        units = self.hint("units", {})
        lines.append(f"f = {self.f:.5f} (stage {self.stage}); "
                     + "; ".join(f"{k} = " + value_text(fin[k], fin[k + "_se"], n=fin.get(k + "_n"),
                                                        of=fin.get(k + "_of"))
                                 + ("" if np.isnan(float(fin[k])) else _unit(units.get(k)))
                                 for k in subs))  # fmt: skip
        lines += [ln[2:] if ln.startswith("  ") else ln
                  for ln in self.hint("extra_lines", [])]  # the study's own (placement)
        lines += self.target_lines
        srch = self.search
        if self.fresh and "f" in srch:
            lines.append(f"(fresh samples, {self.n_samples_used} per design; {SEARCH_LABEL}, "
                         f"{self.n_samples_search} per design: f = "
                         f"{value_text(srch['f'], srch.get('f_se'))})")  # fmt: skip
        lines += runs_lines(self.runs, self.names, units)
        lines += verdict_lines(self.groups.get("verdict"), self.names, units)
        lines += [f"warning: {w}" for w in self.warnings]
        return lines


@dataclass(eq=False)
class ReplayRecord(Record):
    """A study whose run is not an optimisation (``Study.replay``, e.g. a teleoperation
    trajectory): the study's groups, each with an optional ``summary`` attr."""

    KIND: ClassVar[str] = "run"

    def summary(self) -> list[str]:
        return [self.timing_line()] + [
            str(g["attrs"]["summary"]) for g in self.groups.values()
            if isinstance(g, dict) and "summary" in g.get("attrs", {})
        ]  # fmt: skip

    def arrays(self, group: str) -> dict[str, np.ndarray]:
        """The arrays of one of the study's groups (its attrs left out) as numpy."""
        return {k: np.asarray(v) for k, v in self.groups[group].items() if k != "attrs"}


@dataclass(eq=False)
class SweepRecord(Record):
    """Every member of a sweep: group ``members/<i>`` holds one run's groups and attrs
    ``overrides`` and ``config_resolved_yaml``."""

    KIND: ClassVar[str] = "sweep"
    GROUPS: ClassVar[tuple[str, ...]] = ("members",)

    @property
    def members(self) -> dict[str, dict[str, Any]]:
        return {k: v for k, v in self.groups["members"].items() if k != "attrs"}

    def summary(self) -> list[str]:
        return [self.timing_line()] + [
            f"  [{k}] {m['attrs']['overrides']}: f = {float(m['final']['f']):.5f}"
            for k, m in self.members.items()
        ]

    def _ordered(self) -> list[tuple[str, dict[str, Any]]]:
        """The members in the order the sweep declares them (their number), whether the
        record is in memory (grouped by vmapped batch) or read back (sorted by name)."""
        return sorted(self.members.items(), key=lambda kv: (not kv[0].isdigit(), len(kv[0]), kv[0]))

    def member_records(self) -> dict[str, RunRecord]:
        """Each member as a ``RunRecord``, in the sweep's order: its groups, its attrs
        (``overrides``, ``config_resolved_yaml``) and the sweep's ``study``, ``seed``,
        ``keys`` and ``config_dir``; ``.config`` is the member's own resolved config."""
        import yaml

        root = {k: self.attrs[k] for k in ("study", "seed", "keys", "config_dir")
                if k in self.attrs}  # fmt: skip
        out = {}
        for k, m in self._ordered():
            attrs = {"kind": "run", **root, **dict(m.get("attrs", {}))}
            if "config_resolved_yaml" in attrs:
                attrs["config_resolved"] = yaml.safe_load(str(attrs["config_resolved_yaml"]))
                seed = attrs["config_resolved"].get("seed", attrs.get("seed"))
                if seed is not None and int(seed) != self.seed:  # a sweep over the seed
                    from designopt.core.keys import key_data, streams

                    attrs |= {"seed": int(seed), "keys": key_data(streams(int(seed)))}
            out[k] = RunRecord.from_tree({**m, "attrs": attrs}).bind(self._binder)
        return out

    def overrides(self) -> dict[str, dict[str, Any]]:
        """What each member changes (dotted config key → value), in the sweep's order."""
        return {k: dict(m["attrs"]["overrides"]) for k, m in self._ordered()}


@dataclass(eq=False)
class CheckpointRecord(Record):
    """An interrupted run (``<out>.partial.h5``, root attr ``complete`` false): the
    optimizer state after ``done`` iterations, its history so far, and ``resume_key``."""

    KIND: ClassVar[str] = "run"
    GROUPS: ClassVar[tuple[str, ...]] = ("checkpoint",)

    @property
    def done(self) -> int:
        return int(self.groups["checkpoint"]["attrs"]["done"])

    def checkpoint(self) -> Any:
        """The optimizer's ``Checkpoint`` (what ``--resume`` continues from)."""
        from designopt.optim import Checkpoint

        c = self.groups["checkpoint"]
        state = {k: np.asarray(v) for k, v in c["state"].items() if k != "attrs"}
        return Checkpoint(state, np.asarray(c["history"]), np.asarray(c["history_x"]), self.done)

    def summary(self) -> list[str]:
        last = np.asarray(self.groups["checkpoint"]["history"])[..., -1]
        if self.kind == "front":  # the history is each run's hypervolume: larger is better
            return [f"interrupted after {self.done} iterations; largest hypervolume so far "
                    f"{float(np.max(last)):.5g}"]  # fmt: skip
        return [f"interrupted after {self.done} iterations; best so far {float(np.min(last)):.5f}"]
