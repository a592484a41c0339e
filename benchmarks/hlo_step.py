"""Kernels per PSO iteration: the compiled program of 100 runs × ``--iters`` iterations of
PTPSO, p2 and evosax's PSO (Rastrigin D = 30, 50 particles, float32), read from XLA's
optimized HLO (``jax.jit(f).lower(...).compile().as_text()``).

The scan is one ``while``; every instruction at the top of its body that does work (a
fusion, a copy, a custom call, a reduction, …; not a parameter, tuple, get-tuple-element,
bitcast or constant) is one kernel launch on a GPU (one thunk), and a ``conditional`` is
one more, whose branch index XLA's GPU runtime copies to the host and waits for (a
device→host sync per iteration). An inner ``while`` counts its body times its trip count.
On the CPU the count is only a proxy: the CPU backend runs small fusions as plain loops in
one thread (no launch), so what costs there is the arithmetic, not the count.

    python benchmarks/hlo_step.py [--iters 1000] [--dump DIR] [--only ptpso,p2,evosax]
"""

from __future__ import annotations

import argparse
import re
from collections import Counter
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", False)

import jax.numpy as jnp  # noqa: E402

from designopt.optim import registry, runner  # noqa: E402
from designopt.problems.benchmarks import benchmark, rastrigin  # noqa: E402

D, M, R = 30, 50, 100
LO, HI = -5.12, 5.12
FREE = {"parameter", "get-tuple-element", "tuple", "bitcast", "constant", "after-all"}
_HEAD = re.compile(r"^(?:ENTRY\s+)?%(\S+)\s.*\{\s*$")
_INSTR = re.compile(r"^\s*(?:ROOT\s+)?%(\S+)\s*=\s*(.*)$")


def _opcode(rhs: str) -> tuple[str, str]:
    """(opcode, the rest) of an instruction's right-hand side ``type opcode(operands), …``."""
    end = rhs.index(" ")
    if rhs.startswith("("):  # a tuple type: skip to its balanced closing parenthesis
        depth = 0
        for end, c in enumerate(rhs, 1):  # noqa: B007 - end is the loop's result
            depth += (c == "(") - (c == ")")
            if depth == 0:
                break
    rest = rhs[end:].lstrip()
    op = rest.split("(", 1)[0].strip()
    return op, rest


def computations(text: str) -> tuple[dict[str, list[tuple[str, str, str]]], str]:
    """{computation: [(name, opcode, rest)]} of an HLO module's text, and the entry's name."""
    comps: dict[str, list[tuple[str, str, str]]] = {}
    entry, cur = "", None
    for line in text.splitlines():
        h = _HEAD.match(line)
        if h and not line.startswith(" "):
            cur = h.group(1)
            comps[cur] = []
            if line.startswith("ENTRY"):
                entry = cur
            continue
        if line.startswith("}"):
            cur = None
            continue
        m = _INSTR.match(line)
        if cur is not None and m:
            op, rest = _opcode(m.group(2))
            comps[cur].append((m.group(1), op, rest))
    return comps, entry


def _attr(rest: str, key: str) -> str | None:
    m = re.search(key + r"=%?([\w.\-]+)", rest)
    return None if m is None else m.group(1)


def kernels(comps, name: str) -> tuple[float, Counter, int]:
    """(kernel launches, launches by kind, conditionals) of one run of computation ``name``:
    inner whiles × their trip count, a conditional's largest branch plus one."""
    total, kinds, conds = 0.0, Counter(), 0
    for _, op, rest in comps[name]:
        if op in FREE:
            continue
        if op == "while":
            body = _attr(rest, "body")
            m = re.search(r'"known_trip_count":\{"n":"(\d+)"', rest)
            n = int(m.group(1)) if m else 1
            t, k, c = kernels(comps, body)
            total += n * t + 1
            kinds[f"while (inner) ×{n}"] += 1
            kinds.update({f"  in while: {a}": b * n for a, b in k.items()})
            conds += n * c
        elif op == "conditional":
            br = re.search(r"branch_computations=\{([^}]*)\}", rest)
            names = (
                [b.strip().lstrip("%") for b in br.group(1).split(",")]
                if br
                else [_attr(rest, "true_computation"), _attr(rest, "false_computation")]
            )
            sub = [kernels(comps, b) for b in names if b]
            big = max(sub, key=lambda s: s[0])
            total += 1 + big[0]
            kinds[f"conditional ({len(names)} branches)"] += 1
            kinds.update({f"  in branch: {a}": b for a, b in big[1].items()})
            conds += 1 + big[2]
        elif op == "call" and _attr(rest, "to_apply") in comps:  # e.g. a GPU command buffer
            t, k, c = kernels(comps, _attr(rest, "to_apply"))
            total += t
            kinds["call (its kernels counted inside)"] += 1
            kinds.update({f"  in call: {a}": b for a, b in k.items()})
            conds += c
        else:
            kind = op
            if op == "fusion":
                kind = "fusion " + (_attr(rest, "kind") or "?")
            total += 1
            kinds[kind] += 1
    return total, kinds, conds


def scan_body(text: str) -> tuple[dict, str]:
    """The computations and the body of the longest-running ``while`` (the scan), in the
    entry or in any computation it calls (a GPU's command buffers are called computations)."""
    comps, entry = computations(text)
    best, body = -1, None
    for name in [entry, *(c for c in comps if c != entry)]:
        for _, op, rest in comps[name]:
            if op == "while":
                m = re.search(r'"known_trip_count":\{"n":"(\d+)"', rest)
                n = int(m.group(1)) if m else 0
                if n > best:
                    best, body = n, _attr(rest, "body")
    if body is None:
        raise SystemExit("no while loop in the program")
    return comps, body


def ours(name: str, iters: int) -> str:
    P = benchmark("rastrigin", D)
    e = registry.resolve(name)
    opt = registry.build(name, M, iters, "clip")
    params = e.cls.make_params(jnp.float32, e.preset)
    lo, hi = jnp.asarray(P.lower, jnp.float32), jnp.asarray(P.upper, jnp.float32)
    keys = jax.random.split(jax.random.key(0), R)
    st = dict(opt=opt, fn=P.fn, cons=P.constraints)
    carry = runner._init(keys, params, P.params, lo, hi, **st)
    return (
        runner._advance.lower(carry, params, P.params, lo, hi, length=iters, **st)
        .compile()
        .as_text()
    )


def evosax(iters: int) -> str | None:
    try:
        from evosax.algorithms import PSO
    except Exception as e:  # noqa: BLE001 - missing, or not working with this JAX
        print(f"  evosax: {type(e).__name__}: {e}")
        return None
    es = PSO(population_size=M, solution=jnp.zeros(D))
    params = es.default_params

    def one(key):
        k0, k1, k2 = jax.random.split(key, 3)
        x0 = jax.random.uniform(k0, (M, D), minval=LO, maxval=HI)
        state = es.init(k1, x0, rastrigin(x0), params)

        def body(st, k):
            x, st = es.ask(k, st, params)
            x = jnp.clip(x, LO, HI)
            st, _ = es.tell(k, x, rastrigin(x), st, params)
            return st, None

        state, _ = jax.lax.scan(body, state, jax.random.split(k2, iters))
        return state.best_fitness

    keys = jax.random.split(jax.random.key(0), R)
    return jax.jit(jax.vmap(one)).lower(keys).compile().as_text()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--only", default="ptpso,p2,evosax")
    ap.add_argument("--dump", type=Path, help="write each program's HLO text here")
    ap.add_argument("--detail", action="store_true", help="list the kernels by kind")
    ap.add_argument(
        "--formulation",
        choices=("cpu", "other"),
        default=None,
        help="force PSO's CPU or non-CPU step (pso.on_cpu) whatever the backend",
    )
    a = ap.parse_args()
    if a.formulation is not None:
        from designopt.optim import pso

        pso.FORCE_PLATFORM = a.formulation
    form = a.formulation or "the backend's"
    print(f"kernels per iteration of the scan, backend {jax.default_backend()} "
          f"({jax.devices()[0].device_kind}), jax {jax.__version__}, {form} PSO step")  # fmt: skip
    for name in a.only.split(","):
        text = evosax(a.iters) if name == "evosax" else ours(name, a.iters)
        if text is None:
            print(f"  {name:<8} skipped (evosax not installed)")
            continue
        if a.dump is not None:
            a.dump.mkdir(parents=True, exist_ok=True)
            tag = "" if a.formulation is None else f"_{a.formulation}"
            (a.dump / f"{name}_{jax.default_backend()}{tag}.hlo.txt").write_text(text)
        comps, body = scan_body(text)
        n, kinds, conds = kernels(comps, body)
        fus = sum(v for k, v in kinds.items() if "fusion" in k)
        print(f"  {name:<8} {n:5.0f} kernels per iteration ({fus} fusions, {conds} "
              f"conditionals = host syncs on a GPU)")  # fmt: skip
        if a.detail:
            for k, v in sorted(kinds.items(), key=lambda kv: (kv[0].startswith(" "), kv[0])):
                print(f"      {v:4}  {k}")


if __name__ == "__main__":
    main()
