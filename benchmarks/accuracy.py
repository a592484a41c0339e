"""Accuracy per second: time to reach a target SE on each study's main index, per sampler.

For each study (master9: gci; rcm: eta; plas: vel_reduction) and each sampler (``uniform``
i.i.d., ``rqmc`` with 8 replicates) the main index of one design is estimated at a pilot
sample count; SE ∝ n^(-p) with p = 1/2 for uniform and p measured from two pilot sizes
for RQMC gives the n that reaches the target SE, which is then run and timed (compile
excluded, best of ``--repeat``). Float64, one design, one process; the machine's load is
printed with the numbers.

    python benchmarks/accuracy.py [--repeat 3]

The task indices (gci, gci_q05, manipulability, joint_margin, clearance, the arms' shares at
the IK's solutions) are checked the other way, by their spread over seeds against the
printed SE: benchmarks/se_honesty.py.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

from designopt.studies import STUDIES, streams  # noqa: E402

TARGET = {"master9": ("gci", 1e-4), "rcm": ("eta", 1e-4), "plas": ("vel_reduction", 2e-5)}


def evaluator(study: str, sampler: str, n: int):
    """() -> (value, se) of the main index at the config's design centre, jitted."""
    import yaml

    st = STUDIES[study]
    raw = yaml.safe_load(open(f"configs/{study}.yaml"))["study"]
    sec = {"master9": "indices", "rcm": "eta", "plas": "mismatch"}[study]
    upd = {"n_samples": int(n), "sampler": sampler, "replicates": 8 if sampler == "rqmc" else 1}
    extra = {"n_norm": 2} if study == "master9" else {}  # the bounds do not matter here
    s = st.settings.model_validate({**raw, sec: {**raw[sec], **upd}, **extra})
    pr = st.problem(s, streams(0), jnp.float64)
    X = jnp.asarray([(np.asarray(pr.lower) + np.asarray(pr.upper)) / 2], jnp.float64)
    name = TARGET[study][0]
    f = jax.jit(lambda p: (lambda o: (o[name][0], o[name + "_se"][0]))(pr.fn(p, X, None)[1]))
    return lambda: jax.block_until_ready(f(pr.params))


def timed(fn, repeat: int) -> tuple[float, float, list[float]]:
    v, se = fn()  # compile
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        v, se = fn()
        ts.append(time.perf_counter() - t)
    return float(v), float(se), ts


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; float64, 1 design")
    ratios = {}
    for study, (name, target) in TARGET.items():
        t_hit = {}
        for sampler in ("uniform", "rqmc"):
            pil = [4096, 16384]
            ses = [timed(evaluator(study, sampler, n), 1)[1] for n in pil]
            p = 0.5 if sampler == "uniform" else float(np.log(ses[0] / ses[1]) / np.log(4))
            p = max(p, 0.5)
            n = int(pil[1] * (ses[1] / target) ** (1 / p))
            n = max(2048, int(2 ** np.ceil(np.log2(max(n, 1)))))
            v, se, ts = timed(evaluator(study, sampler, n), a.repeat)
            t_hit[sampler] = min(ts) * (se / target) ** (1 / p)  # scaled to the exact target
            print(f"{study:8s} {name:14s} {sampler:8s} n = {n:8d}  SE {se:.2e} (order "
                  f"n^-{p:.2f})  time {min(ts) * 1e3:8.1f} ms (spread "
                  f"{(max(ts) - min(ts)) * 1e3:.1f} ms)  → SE {target:.0e} in "
                  f"{t_hit[sampler] * 1e3:.1f} ms")  # fmt: skip
        ratios[study] = t_hit["rqmc"] / t_hit["uniform"]
    print("rqmc/uniform time-to-SE: " + ", ".join(f"{k} = {v:.3g}" for k, v in ratios.items()))


if __name__ == "__main__":
    main()
