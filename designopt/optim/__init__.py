"""PSO family (seed 000 eq. 44-50): p1..p7 with PTPSO = p3, and the batch runner."""

from designopt.optim.pso import Params, State, constriction, init, penalty_coefficient, step
from designopt.optim.runner import RunResult, convergence_iteration, run
from designopt.optim.variants import ALIASES, VARIANTS, make_params, resolve

__all__ = [
    "ALIASES",
    "VARIANTS",
    "Params",
    "RunResult",
    "State",
    "constriction",
    "convergence_iteration",
    "init",
    "make_params",
    "penalty_coefficient",
    "resolve",
    "run",
    "step",
]
