"""One study-A optimisation as the CLI runs it: problem, PSO (single or vmapped batch of
settings), optional optax polish, and the archive tree (docs/archive.md)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from designopt import optim
from designopt.config import RunConfig, study_dict
from designopt.problems.base import Problem
from designopt.refine import refine
from designopt.studies.master9 import objective


def build_problem(cfg: RunConfig) -> Problem:
    return objective.problem(study_dict(cfg))


def resolved_yaml(cfg: RunConfig) -> str:
    return yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False)


def score(problem: Problem, X: np.ndarray) -> dict[str, np.ndarray]:
    """f and every sub-objective (with standard errors) of designs X (n, D)."""
    f, sub = jax.jit(problem.fn)(problem.params, jnp.asarray(X), jax.random.key(0))
    return {"f": np.asarray(f)} | {k: np.asarray(v) for k, v in sub.items()}


def optimise(cfg: RunConfig, problem: Problem, members: list[dict[str, float]] | None = None,
             progress: Callable[[int], None] | None = None,
             checkpoint: Callable[[optim.Checkpoint], None] | None = None,
             resume: optim.Checkpoint | None = None) -> optim.RunResult:  # fmt: skip
    """PSO per the config; with ``members`` (optimizer-setting overrides) one vmapped batch."""
    o = cfg.optimizer
    common = dict(n_particles=o.n_particles, n_iters=o.n_iters, n_runs=o.n_runs, bounds=o.bounds,
                  dtype=jnp.dtype(cfg.precision), chunk_iters=max(1, o.n_iters // 20),
                  progress=progress, checkpoint=checkpoint, resume=resume)  # fmt: skip
    key = jax.random.key(cfg.seed)
    if members is None:
        return optim.run(o.name, problem, key, **common, **o.settings)
    return optim.run_batch(o.name, problem, key, [o.settings | m for m in members], **common)


def result_tree(cfg: RunConfig, problem: Problem, res: optim.RunResult) -> dict[str, Any]:
    """Archive groups of one (unbatched) run: optimizer, best_run, refine, final, problem."""
    best = int(np.argmin(res.best_f))
    sub_hist = score(problem, res.history_x[best])
    tree: dict[str, Any] = {
        "optimizer": {
            "history": res.history, "best_f": res.best_f, "best_x": res.best_x,
            "converged_at": res.converged_at, "history_x": res.history_x,
            "attrs": {"settings": res.settings},
        },
        "best_run": sub_hist | {"iteration": np.arange(res.history.shape[-1]),
                                "attrs": {"run_index": best}},
        "problem": {
            "names": np.array(problem.names, dtype="S"), "lower": problem.lower,
            "upper": problem.upper, "norm_bounds": np.asarray(problem.params["bounds"]),
            "attrs": {"info": problem.info},
        },
    }  # fmt: skip
    x_final = res.best_x[best][None]
    stage = "pso"
    if cfg.refine is not None:
        r = cfg.refine
        order = np.argsort(res.best_f)[: r.n_best]
        rr = refine(problem, res.best_x[order], r.steps, r.learning_rate, r.method,
                    dtype=jnp.dtype(cfg.precision))  # fmt: skip
        tree["refine"] = {
            "run_index": order, "x0": rr.x0, "f0": rr.f0, "x": rr.x, "f": rr.f,
            "history": rr.history, "gain": rr.gain,
            "attrs": {"method": r.method, "steps": r.steps, "learning_rate": r.learning_rate},
        }  # fmt: skip
        if rr.f.min() < res.best_f[best]:
            x_final, stage = rr.x[np.argmin(rr.f)][None], "refine"
    fin = {k: v[0] for k, v in score(problem, x_final).items()}
    tree["final"] = fin | {"x": x_final[0], "attrs": {"stage": stage,
                           "n_samples_used": problem.info["n_samples_used"]}}  # fmt: skip
    return tree


def summary_lines(problem: Problem, tree: dict[str, Any], n_runs: int) -> list[str]:
    fin = tree["final"]
    best = tree["best_run"]["attrs"]["run_index"]
    opt = tree["optimizer"]
    lines = [f"best design (run {best} of {n_runs}; final stage: {fin['attrs']['stage']}):"]
    lines += [f"  {n} = {v:9.3f} mm" for n, v in zip(problem.names, fin["x"], strict=True)]
    lines.append(f"  f     = {float(fin['f']):.5f}   (PSO {opt['best_f'][best]:.5f}, "
                 f"converged at iteration {opt['converged_at'][best]})")  # fmt: skip
    if "refine" in tree:
        g = tree["refine"]["gain"]
        lines.append(f"  polish ({tree['refine']['attrs']['method']}, "
                     f"{tree['refine']['attrs']['steps']} steps) gained Δf = {g.max():.2e}")  # fmt: skip
    for k in ("f_k", "f_l", "f_p", "gci", "gcsei", "gpi"):
        v, se = float(fin[k]), float(fin[k + "_se"])
        rel = f"({100 * se / abs(v):.2f} %)" if v else ""
        lines.append(f"  {k:<5} = {v:.5f} ± {se:.1e} {rel}")
    lines.append(f"  V     = {float(fin['volume']):.4e} ± {float(fin['volume_se']):.1e} mm³   "
                 f"L = {float(fin['L']):.3f} mm")  # fmt: skip
    return lines
