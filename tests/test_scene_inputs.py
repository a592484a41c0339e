"""The scene's numbers are inputs of the compiled programs (issue: compile once per
structure): the program traced for one scene, fed another scene's params (the port, the
insertion range, the obstacles, the task region's targets, the arms' bases moved; in the
planning case the body wall under designed ports, the meshes' poses, the anatomy, the
instruments' band and radius, the endoscope's port, view and shaft), compiles nothing new and gives that scene's own indices,
bit for bit."""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from designopt.app.config import validate
from designopt.core.keys import streams
from designopt.studies.serial import objective

jax.config.update("jax_enable_x64", True)


def _puma(edit: bool, chunk: int | None = None) -> dict:
    with open("configs/urdf_puma560_port.yaml") as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["chain"]["urdf"] = str(Path("configs/robots/puma560.urdf").resolve())
    s["indices"]["n_samples"] = 24
    # the scene's numbers are the point, not the IK's second pass (the two arms keep it):
    # no neighbour pass, the programs of tests/test_ports_designed.py's fixed port and of
    # tests/test_staged.py's PUMA (chunks of 16), which a session compiles once
    s["task"].setdefault("ik", {})["neighbours"] = 0
    if chunk is not None:
        s["indices"]["chunk"] = chunk
    if edit:  # move the port, the skin, the region; narrow the insertion
        s["task"]["port"] = [0.49, 0.11, -0.21]
        s["task"]["insertion"] = [0.06, 0.25]
        s["task"]["region"]["center"] = [0.49, 0.11, -0.37]
        s["collision"]["obstacles"] = [{"shape": "halfspace", "point": [0, 0, -0.21],
                                        "normal": [0, 0.05, 1]}]  # fmt: skip
    return cfg


def _arms(edit: bool) -> dict:
    with open("configs/two_arms_front.yaml") as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["indices"]["n_samples"] = 24
    s["objective"] = {"reach_all": -1.0}
    cfg["optimizer"] = {"name": "ptpso", "n_particles": 4, "n_iters": 1}
    if edit:
        s["collision"]["obstacles"][0]["center"] = [0.02, 0.0, 0.06]
        s["task"]["region"]["center"] = [0.0, 0.03, 0.24]
        s["arms"][1]["base"]["xyz"] = ["b", 0.05, 0]
    return cfg


def _planning(edit: bool) -> dict:
    """The planning case: designed ports on an ellipsoid wall, a mesh outside, a capsule
    and a mesh inside, the instruments' band and radius, an endoscope with a shaft."""
    path = Path("configs/port_placement.yaml").resolve()
    with open(path) as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["indices"]["n_samples"] = 24
    s["chain"]["urdf"] = str(path.parent / s["chain"]["urdf"])
    for o in s["collision"]["obstacles"]:
        if o["shape"] == "mesh":
            o["file"] = str(path.parent / o["file"])
    s["task"]["camera"] = {"port": ["px", 0.1, 0.3], "band": [0.04, 0.16], "fov": 70,
                           "shaft": {"length": 0.4, "radius": 0.005}}  # an endoscope  # fmt: skip
    if edit:  # the endoscope's every number: its port, aim, band, view, depth and shaft
        s["task"]["camera"] = {"port": ["px", 0.12, 0.28], "band": [0.03, 0.12], "fov": 80,
                               "aim": [0.0, 0.01, 0.04], "insertion": [0.02, 0.15],
                               "shaft": {"length": 0.35, "radius": 0.006}}  # fmt: skip
    if edit:  # move the wall, the abdomen's mesh, the vessel, the organ; the band, the tool
        s["task"]["body_wall"]["center"] = [0.0, 0.01, 0.065]
        s["task"]["instrument_angle"] = [40, 80]
        s["collision"]["tool_radius"] = 0.005
        ob = s["collision"]["obstacles"]
        ob[0]["xyz"] = [0.0, 0.01, 0.005]
        ob[1]["a"], ob[1]["b"] = [-0.06, 0.01, 0.1], [0.06, -0.01, 0.1]
        ob[2]["xyz"] = [0.01, -0.08, 0.05]
        ob[2]["rpy"] = [0, 0, 10]
    return cfg


@pytest.mark.parametrize("make, X", [
    (_puma, [[0.43, 0.43, 0.4], [0.5, 0.35, 0.3]]),
    (_arms, [[0.6, 0.45, 0.45], [0.5, 0.3, 0.55]]),
    (_planning, [[0.6, 0.0, 0.03, 0.0, 0.0], [0.5085, -0.018, 0.021, -0.1185, 0.1261]]),
])  # fmt: skip
def test_a_scene_edit_runs_in_the_same_program(make, X):
    X = jnp.asarray(X, jnp.float64)
    probs = []
    for edit in (False, True):
        c = validate(copy.deepcopy(make(edit)), "test")
        probs.append(objective.problem(c.study, streams(c.seed), jnp.float64))
    a, b = probs
    assert jax.tree_util.tree_structure(a.params) == jax.tree_util.tree_structure(b.params)
    fa = jax.jit(a.fn)
    fa(a.params, X, jax.random.key(0))
    n = fa._cache_size()
    f_ab, aux_ab = fa(b.params, X, jax.random.key(0))  # a's program, b's scene
    assert fa._cache_size() == n  # nothing traced or compiled again
    f_b, aux_b = jax.jit(b.fn)(b.params, X, jax.random.key(0))  # b's own program
    np.testing.assert_array_equal(np.asarray(f_ab), np.asarray(f_b))
    for k in aux_b:
        np.testing.assert_array_equal(np.asarray(aux_ab[k]), np.asarray(aux_b[k]), err_msg=k)
    aux_a = fa(a.params, X, jax.random.key(0))[1]
    assert any(not np.array_equal(np.asarray(aux_a[k]), np.asarray(aux_b[k]))
               for k in aux_b)  # fmt: skip  # the edit mattered


def test_the_figures_solution_of_an_edited_scene_reuses_its_program():
    """blocks.solution (the figures', the report's and the archive's per-target
    solve) runs the structure's block program (``blocks``): an edited scene runs in the
    program already compiled and gives what a fresh program gives (targets in chunks of
    16: two calls of the program for the 24)."""
    from designopt.core import exported
    from designopt.studies.serial import blocks, taskindex

    a, b = (validate(copy.deepcopy(_puma(e, chunk=16)), "test") for e in (False, True))
    assert taskindex.structure_key(a.study) == taskindex.structure_key(b.study)
    x = [0.43, 0.43, 0.4]
    blocks._PROGRAMS.clear()
    exported._CALLS.clear()
    sa = blocks.solution(a.study, x, streams(a.seed))
    (call,) = exported._CALLS.values()  # the block program (exported or not)
    assert call._cache_size() == 1
    sb = blocks.solution(b.study, x, streams(b.seed))
    assert len(blocks._PROGRAMS) == 1 and len(exported._CALLS) == 1
    assert call._cache_size() == 1
    blocks._PROGRAMS.clear()
    exported._CALLS.clear()
    fresh = blocks.solution(b.study, x, streams(b.seed))
    for k in fresh:
        np.testing.assert_array_equal(sb[k], fresh[k], err_msg=k)
    assert not np.array_equal(sa["target_p"], sb["target_p"])
