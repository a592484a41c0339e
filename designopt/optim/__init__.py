"""PSO family (seed 000 eq. 44-50): p1..p7 with PTPSO = p3, and the batch runner."""

from designopt.optim.pso import Params, State, constriction, init, penalty_coefficient, step
from designopt.optim.runner import Checkpoint, RunResult, convergence_iteration, run, run_batch
from designopt.optim.variants import ALIASES, VARIANTS, make_params, resolve, stack_params

__all__ = [
    "ALIASES",
    "Checkpoint",
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
    "run_batch",
    "stack_params",
    "step",
]
