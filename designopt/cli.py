"""The ``designopt`` command line. User mistakes print one line and exit with status 2."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from designopt.config import ConfigError, load, study_dict


def _check_output(path: Path) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"output '{path}': cannot create folder ({e.strerror})") from None
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"output '{path}': folder is not writable")


def cmd_run(args: argparse.Namespace) -> int:
    cfg, text = load(args.config)
    if args.seed is not None:
        cfg.seed = args.seed
    out = Path(args.out or cfg.output)
    _check_output(out)
    try:
        from designopt.optim import resolve

        resolve(cfg.optimizer.name)
    except ValueError as e:
        raise ConfigError(f"{args.config}: key 'optimizer.name': {e}") from None

    import jax
    import jax.numpy as jnp
    from tqdm import tqdm

    from designopt import archive, optim
    from designopt.mechanisms import master9

    t0 = time.perf_counter()
    try:
        problem = master9.problem(study_dict(cfg))
    except ValueError as e:
        raise ConfigError(f"{args.config}: study: {e}") from None
    t_setup = time.perf_counter() - t0
    o = cfg.optimizer
    dtype = jnp.dtype(cfg.precision)
    try:
        optim.make_params(o.name, dtype, **o.settings)
    except ValueError as e:
        raise ConfigError(f"{args.config}: key 'optimizer.settings': {e}") from None
    chunk = max(1, o.n_iters // 20)
    t1 = time.perf_counter()
    with tqdm(total=o.n_iters, desc=f"{o.name} on master9", unit="it", disable=args.quiet) as bar:
        res = optim.run(
            o.name, problem, jax.random.key(cfg.seed), o.n_particles, o.n_iters, o.n_runs,
            bounds=o.bounds, dtype=dtype, chunk_iters=chunk, progress=bar.update, **o.settings,
        )  # fmt: skip
    t_run = time.perf_counter() - t1
    best = int(np.argmin(res.best_f))
    hx = res.history_x[best]
    _, sub_hist = jax.jit(problem.fn)(problem.params, jnp.asarray(hx), jax.random.key(0))
    sub_hist = {k: np.asarray(v) for k, v in sub_hist.items()}
    final = {k: float(v[-1]) for k, v in sub_hist.items()}
    groups = {
        "optimizer": {
            "history": res.history, "best_f": res.best_f, "best_x": res.best_x,
            "converged_at": res.converged_at, "history_x": res.history_x, "settings": res.settings,
        },
        "best_run": {k: v for k, v in sub_hist.items()} | {"run_index": best},
        "problem": {
            "names": np.array(problem.names, dtype="S"), "lower": problem.lower, "upper": problem.upper,
            "norm_bounds": np.asarray(problem.params["bounds"]), "info": problem.info,
        },
    }  # fmt: skip
    attrs = {
        "config_yaml": text, "config_resolved": cfg.model_dump_json(), "seed": cfg.seed,
        "wall_time_s": time.perf_counter() - t0, "setup_time_s": t_setup, "run_time_s": t_run,
        "study": "master9",
    }  # fmt: skip
    archive.write(out, groups, attrs)
    print(f"best design (run {best} of {o.n_runs}):")
    for n, v in zip(problem.names, res.best_x[best], strict=True):
        print(f"  {n} = {v:9.3f} mm")
    print(f"  f   = {res.best_f[best]:.4f}   (converged at iteration {res.converged_at[best]})")
    for k in ("f_k", "f_l", "f_p", "gci", "gcsei", "gpi"):
        print(f"  {k:<5} = {final[k]:.5f} ± {final[k + '_se']:.1e}")
    print(f"  V   = {final['volume']:.4e} ± {final['volume_se']:.1e} mm³   L = {final['L']:.3f} mm")
    print(
        f"samples per design: {problem.info['n_samples_used']}; setup {t_setup:.1f} s, run {t_run:.1f} s"
    )
    print(f"archive: {out}")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    import h5py

    p = Path(args.archive)
    if not p.is_file():
        raise ConfigError(f"{p}: archive not found")
    try:
        with h5py.File(p, "r") as h:
            print(
                f"{p}: study {h.attrs.get('study')}, seed {h.attrs.get('seed')}, complete {h.attrs.get('complete')}"
            )
            print(f"wall time {h.attrs['wall_time_s']:.1f} s")
            names = [n.decode() for n in h["problem/names"][()]]
            bf, bx = h["optimizer/best_f"][()], h["optimizer/best_x"][()]
            i = int(np.argmin(bf))
            print(
                "best design: "
                + ", ".join(f"{n} = {v:.3f}" for n, v in zip(names, bx[i], strict=True))
                + f"; f = {bf[i]:.4f}"
            )
    except OSError as e:
        raise ConfigError(f"{p}: not a readable HDF5 archive ({e})") from None
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="designopt",
        description="Vectorized JAX design-space optimizer for surgical-robot mechanisms.",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one study from a YAML config")
    r.add_argument("config", help="study config (YAML), e.g. configs/master9.yaml")
    r.add_argument("--seed", type=int, default=None, help="override the config's seed")
    r.add_argument("--out", default=None, help="override the archive path")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_run)
    s = sub.add_parser("show", help="print the summary of an archive")
    s.add_argument("archive")
    s.set_defaults(func=cmd_show)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as e:
        print(f"designopt: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("designopt: interrupted; no archive written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
