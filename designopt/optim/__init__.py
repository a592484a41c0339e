"""Optimizers behind one protocol (protocol.py): the PSO family p1..p7 (PTPSO = p3) as one
entry, CMA-ES beside it, NSGA-II for multi-objective problems, and the runner that vmaps
runs and settings over any of them.

The pipeline's interface: ``run``, ``run_batch``, ``validate``, ``setting_names``,
``names``/``OPTIMIZERS``, ``RunResult``, ``Checkpoint`` (docs/optimizers.md).
"""

from designopt.optim.protocol import Best, Front, Optimizer, Task
from designopt.optim.pso import constriction, penalty_coefficient
from designopt.optim.registry import (
    MULTI_OBJECTIVE,
    OPTIMIZERS,
    is_multi_objective,
    make_params,
    multi_objective_names,
    names,
    option_names,
    register,
    resolve,
    setting_names,
    validate,
)
from designopt.optim.runner import (
    Checkpoint,
    RunResult,
    convergence_iteration,
    first_nadir,
    run,
    run_batch,
)

__all__ = [
    "MULTI_OBJECTIVE",
    "OPTIMIZERS",
    "Best",
    "Checkpoint",
    "Front",
    "Optimizer",
    "RunResult",
    "Task",
    "constriction",
    "convergence_iteration",
    "first_nadir",
    "is_multi_objective",
    "make_params",
    "multi_objective_names",
    "names",
    "option_names",
    "penalty_coefficient",
    "register",
    "resolve",
    "run",
    "run_batch",
    "setting_names",
    "validate",
]
