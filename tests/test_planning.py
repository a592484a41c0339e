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
