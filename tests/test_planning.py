"""The shipped planning case (configs/port_placement.yaml, docs/planning.md): the layout
its run finds beats the naive one (both ports on a line straight above the target) by
more than 4 SE in the front's objective and in the triangulation constraint, on the
same targets; the naive layout loses targets to the vessel above the target."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from designopt.app.config import validate
from designopt.core.keys import streams
from designopt.studies.serial import objective

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
NAIVE = {"b": 0.6, "by": 0.0, "px": 0.03, "py0": 0.0, "py1": 0.0}
BEST = {"b": 0.5085, "by": -0.01805, "px": 0.02061, "py0": -0.1185, "py1": 0.1261}  # docs


def test_the_planned_layout_beats_the_naive_one_by_more_than_4_se():
    path = ROOT / "configs/port_placement.yaml"
    cfg = yaml.safe_load(path.read_text())
    c = validate(cfg, str(path))
    s = c.study
    pb = objective.problem(s, streams(c.seed), jnp.float64)
    X = jnp.asarray([[d[k] for k in s.variables] for d in (NAIVE, BEST)])
    _, aux = jax.jit(pb.fn)(pb.params, X, jax.random.key(0))
    a = {k: np.asarray(v) for k, v in aux.items()}
    for k in ("arms_ok", "instrument_ok", "reach_all"):
        gap = a[k][1] - a[k][0]
        se = np.hypot(a[k + "_se"][0], a[k + "_se"][1])
        assert gap > 4 * se, (k, a[k], a[k + "_se"])
    assert a["instrument_ok"][0] < 0.05 and a["instrument_ok"][1] > 0.5  # the constraint
    assert 45 <= a["instrument_angle"][1] <= 75
    assert a["reach_all"][0] < 0.6  # the vessel above the target blocks the naive ports


def test_the_planned_layouts_gci_is_the_same_at_seeds_0_1_and_2():
    """One fixed design's task dexterity does not depend on the seed beyond its SE: with
    the shipped IK settings (the best of up to 8 distinct solutions at every target, from
    16 nearest seeds spread over the branches) the planned layout's ``gci`` at seeds 0, 1
    and 2 (new targets and new IK seeds each) agrees within 2 SE pairwise. With
    ``n_best: 1`` it was 0.578, 0.436 and 0.429 (docs/planning.md)."""
    path = ROOT / "configs/port_placement.yaml"
    c = validate(yaml.safe_load(path.read_text()), str(path))
    s = c.study
    assert (s.task.ik.n_best, s.task.ik.n_nearest) == (8, 16)
    X = jnp.asarray([[d[k] for k in s.variables] for d in (NAIVE, BEST)])
    g, se = [], []
    for seed in (0, 1, 2):
        pb = objective.problem(s, streams(seed), jnp.float64)
        _, aux = jax.jit(pb.fn)(pb.params, X, jax.random.key(0))
        g.append(float(aux["gci"][1]))
        se.append(float(aux["gci_se"][1]))
    for i in range(3):
        for j in range(i):
            assert abs(g[i] - g[j]) <= 2 * np.hypot(se[i], se[j]), (g, se)
    assert min(g) > 0.6, g  # the best branch at every target: about 0.627
