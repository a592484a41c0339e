"""Racing candidate designs on fresh samples: the decision statistics of a final stage
(numpy only).

A search ends with a handful of candidate layouts that it scored on its own samples. The
race scores them again on a validation stream and decides, with stated confidence, which
of them is better, which are equal for practical purposes, and which are worse, giving
more samples only to the candidates that are still undecided (ranking and selection with
an indifference zone, in the spirit of Kim & Nelson, "A fully sequential procedure for
indifference-zone selection in simulation", 2001, and of iterated racing, López-Ibáñez et
al., "The irace package: Iterated racing for automatic algorithm configuration", 2016).

Pieces, each usable on its own:

- :func:`clear`: candidates within a radius of each other in the box-normalised design
  space are one candidate (greedy clearing in priority order, as in niching: Pétrowski,
  "A clearing procedure as a niching method for genetic algorithms", 1996).
- :func:`wilson`, :func:`constraint_status`: the Wilson score interval of a share
  (Wilson, "Probable inference, the law of succession, and statistical inference", 1927)
  and whether a share constraint is *met*, *missed* or *at its bound*.
- :func:`paired`: the mean and standard error of a paired difference on common samples;
  :func:`t_sf`, :func:`t_ppf`: Student's t tail and quantile (numpy and ``math`` only).
- :func:`race`: the sequential elimination (rules below); :class:`RaceResult` its answer.
- :func:`differing_variables`, :func:`mirror`: how the layouts of a tied set differ, and
  whether two of them are mirror images under a symmetry the caller names.

The race's rules (every objective internally minimised; ``maximize`` flips an objective):

- **Samples.** Stage s scores the candidates still sampled on samples [start, stop) of one
  validation stream, the same samples for all of them (common random numbers), so every
  comparison is a paired difference on the samples both candidates have. A "sample" is
  whatever unit the caller passes: one target, or the mean over one replication of R
  targets (then the SE is the replication SE). A candidate that stops getting samples
  keeps its prefix of the stream; its comparisons use the common prefix.
- **Looks.** The race looks at the data after every stage. With S = ⌈max_samples / stage⌉
  possible looks, each look tests at level alpha / S (Bonferroni over looks) and corrects
  across the look's family of tests with Holm's step-down procedure
  (:func:`designopt.numerics.statistics.holm`); decisions are final once taken. Over the
  whole race the family-wise error of each kind of decision (eliminations; equivalences
  and trade-offs) is then at most alpha. Tests use the normal approximation to the
  paired mean (stages of at least 30 samples keep it honest), or, where each unit is
  the mean of one replication (``student=True``: a few units of many samples each),
  Student's t with N − 1 degrees of freedom, N the pair's common units.
- **Constraints** (share constraints ``share ≥ bound`` or ``≤``, counted by the caller):
  the status of each candidate is read from its Wilson interval at the per-look level
  (z = Φ⁻¹(1 − alpha/(2S)), per candidate and constraint, not corrected across
  candidates): *met*, *missed* or *at its bound*. A candidate that missed a
  constraint is "worse" as soon as some remaining candidate has not missed any; one at
  its bound keeps getting samples until its status is decided or the cap is reached.
- **The leader** is the best remaining candidate on the primary objective among those
  that missed no constraint (if all missed one, the best of all).
- **One objective.** A candidate is eliminated ("worse") when its paired difference from
  the reference is worse by more than the margin δ with confidence: the one-sided test of
  H0: d ≤ δ rejected after Holm across the look's candidates. The reference is the best
  remaining candidate whose constraints are all *met* (the leader when it is met): a
  candidate is never eliminated by one whose feasibility is still open, which could later
  turn out to miss its constraint.
- **Several objectives** (a front's): candidate i is eliminated only when some remaining
  candidate j whose constraints are met *dominates it with confidence*: j is better than
  i by more than δ_k on some objective k, and j is not worse than i by δ_l or more on
  any objective l (a non-inferiority test, one-sided, for every objective). The pair's
  p-value is the intersection-union max of the non-inferiority p-values and m × the
  smallest "better by more than δ" p-value (Bonferroni over the m objectives); Holm
  corrects across all ordered pairs of the look. The non-inferiority part is stricter
  than "not significantly worse": a few noisy samples cannot eliminate a real trade-off.
  Candidates that are not eliminated stay: equivalent to another, or non-dominated.
- **Equivalence.** Two remaining candidates are *equivalent* when a two-one-sided test
  (TOST) shows |d_k| < δ_k on every objective k (the pair's p-value is the largest of the
  2m one-sided ones), Holm-corrected across the look's undecided pairs.
- **Trade-offs** (several objectives): two remaining candidates are a *trade-off* when
  each is better than the other by more than the margin on some objective, with
  confidence (intersection-union of the two directions, each Bonferroni over the m
  objectives). With several objectives a pair's one decision test is the smaller of its
  equivalence and trade-off p-values, times 2 (Bonferroni over the two), Holm-corrected
  across the undecided pairs.
- **Allocation.** The next stage samples only the remaining candidates that are still
  undecided against some other remaining one (neither equivalent, nor a trade-off, nor
  eliminated) or that are at the bound of a constraint.
- **Stop** when one candidate remains, when no candidate needs more samples (every pair
  decided, every constraint decided), or at ``max_samples`` per candidate.
- **Verdicts.** "worse" for the eliminated; "best" for the leader; "equivalent" for the
  others that remain. With several objectives, the remaining candidates are grouped in
  order of the primary objective (the leader first): a candidate joins the first group
  whose head it was shown equivalent to, else the first whose head it was not shown to
  be a trade-off with; one shown to be a trade-off with every head is "best" of a group
  of its own (a distinct point of the front). ``settled`` says whether a remaining
  candidate's equivalence to its group's head was shown, or whether the cap stopped the
  race first (then the data cannot choose between them).
- **Summary.** "one recommendation" when one candidate remains; "a tied set of K layouts"
  when K remain in one group (shown equivalent, or not separable within the cap); with
  several objectives and several groups, "a front of K layouts".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from designopt.numerics.statistics import holm

VERDICTS = ("best", "equivalent", "worse")
STATUSES = ("met", "at its bound", "missed")
_MET, _AT, _MISSED = 0, 1, 2

_erfc = np.frompyfunc(math.erfc, 1, 1)


# ---------------------------------------------------------------- normal distribution


def norm_sf(x: np.ndarray | float) -> np.ndarray:
    """The standard normal survival function P(Z > x), elementwise (±inf give 0 and 1)."""
    x = np.asarray(x, np.float64)
    return (0.5 * _erfc(x / math.sqrt(2.0))).astype(np.float64)


def norm_ppf(p: float) -> float:
    """The standard normal quantile Φ⁻¹(p) for 0 < p < 1: bisection on ``math.erfc`` to
    the last bit, in the lower tail (Φ⁻¹(p) = −Φ⁻¹(1 − p) above 1/2, 1 − p exact there),
    where erfc keeps its relative accuracy."""
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ValueError(f"norm_ppf: p must lie in (0, 1), not {p}")
    if p > 0.5:
        return -norm_ppf(1.0 - p)
    lo, hi = -40.0, 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if 0.5 * math.erfc(-mid / math.sqrt(2.0)) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def holm_reject(pvalues: np.ndarray, alpha: float) -> np.ndarray:
    """Which hypotheses Holm's step-down procedure rejects at family-wise level ``alpha``
    (the adjusted p-values of :func:`designopt.numerics.statistics.holm` below alpha)."""
    p = np.asarray(pvalues, np.float64).ravel()
    if p.size == 0:
        return np.zeros(0, bool)
    return holm(p) < alpha


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function (modified
    Lentz), converging for x < (a + 1)/(a + b + 2)."""
    tiny, qab, qap, qam = 1e-300, a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 400):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        de = d * c
        h *= de
        if abs(de - 1.0) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b), 0 ≤ x ≤ 1."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    lbt = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x)
           + b * math.log1p(-x))  # fmt: skip
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(lbt) * _betacf(a, b, x) / a
    return 1.0 - math.exp(lbt) * _betacf(b, a, 1.0 - x) / b


def _t_sf1(t: float, df: float) -> float:
    if math.isnan(t):
        return math.nan
    if math.isinf(df):
        return 0.5 * math.erfc(t / math.sqrt(2.0))
    if math.isinf(t):
        return 0.0 if t > 0 else 1.0
    a, y = 0.5 * df, t * t / (df + t * t)  # x = 1 − y: near 1, take I from y's side
    x = df / (df + t * t)
    i_x = _betainc(a, 0.5, x) if x < (a + 1.0) / (a + 2.5) else 1.0 - _betainc(0.5, a, y)
    tail = 0.5 * i_x  # P(T > |t|)
    return tail if t >= 0 else 1.0 - tail


_t_sf = np.frompyfunc(_t_sf1, 2, 1)


def t_sf(x: np.ndarray | float, df: np.ndarray | float) -> np.ndarray:
    """Student's t survival function P(T_df > x), elementwise (df = inf: the normal's;
    ±inf give 0 and 1), from the regularised incomplete beta function,
    P(T > |t|) = I_{df/(df+t²)}(df/2, 1/2)/2."""
    x, df = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(df, np.float64))
    return np.asarray(_t_sf(x, df), dtype=np.float64)


def t_ppf(p: float, df: float) -> float:
    """Student's t quantile with ``df`` > 0 degrees of freedom (bisection on :func:`t_sf`;
    df = inf: :func:`norm_ppf`)."""
    p, df = float(p), float(df)
    if not 0.0 < p < 1.0:
        raise ValueError(f"t_ppf: p must lie in (0, 1), not {p}")
    if not df > 0:
        raise ValueError(f"t_ppf: df must be > 0, not {df}")
    if math.isinf(df):
        return norm_ppf(p)
    if p > 0.5:
        return -t_ppf(1.0 - p, df)
    lo, hi = -1.0, 0.0
    while _t_sf1(-lo, df) > p:  # P(T < lo) = P(T > −lo): widen until it is below p
        lo *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if _t_sf1(-mid, df) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------- clearing


def clear(X: np.ndarray, lo: np.ndarray, hi: np.ndarray,
          radius: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Greedy clearing: candidates within ``radius`` of each other are one candidate.

    ``X`` (C, d) holds the candidates in priority order (the best first); each design is
    box-normalised, u = (x − lo)/(hi − lo) (a variable with hi = lo contributes nothing),
    and distances are Euclidean in u. The first candidate not yet taken stands for every
    candidate not yet taken within ``radius`` of it (distance ≤ radius); repeat.

    Returns ``(keep, groups)``: ``keep`` the indices of the standing candidates in
    priority order, ``groups`` (C,) for each candidate the position in ``keep`` of the
    one that stands for it (``keep[groups[i]]``)."""
    X = np.asarray(X, np.float64)
    if X.ndim != 2:
        raise ValueError(f"clear: X must be (candidates, variables), not shape {X.shape}")
    lo = np.broadcast_to(np.asarray(lo, np.float64), X.shape[1:])
    hi = np.broadcast_to(np.asarray(hi, np.float64), X.shape[1:])
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("clear: designs and bounds must be finite")
    if np.any(hi < lo):
        raise ValueError("clear: every upper bound must be ≥ its lower bound")
    radius = float(radius)
    if not (math.isfinite(radius) and radius >= 0.0):
        raise ValueError(f"clear: radius must be a finite number ≥ 0, not {radius}")
    width = np.where(hi > lo, hi - lo, 1.0)
    U = (X - lo) / width
    dist = np.sqrt(np.sum((U[:, None, :] - U[None, :, :]) ** 2, axis=-1))
    groups = np.full(X.shape[0], -1, np.int64)
    keep: list[int] = []
    while True:  # one pass per standing candidate
        free = groups < 0
        if not free.any():
            break
        i = int(np.argmax(free))
        groups[free & (dist[i] <= radius)] = len(keep)
        keep.append(i)
    return np.asarray(keep, np.int64), groups


# ---------------------------------------------------------------- shares


def wilson(k: np.ndarray | int, n: np.ndarray | int,
           z: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Wilson score interval (lower, upper) of a share k/n at normal quantile ``z``
    (z = 1.96 for a two-sided 95 % interval): centre (k + z²/2)/(n + z²), half-width
    z/(n + z²)·√(k(n − k)/n + z²/4). n = 0 gives (0, 1)."""
    k = np.asarray(k, np.float64)
    n = np.asarray(n, np.float64)
    if np.any(n < 0) or np.any(k < 0) or np.any(k > n):
        raise ValueError("wilson: need 0 ≤ k ≤ n")
    z = float(z)
    z2 = z * z
    safe = np.where(n > 0, n, 1.0)
    centre = (k + 0.5 * z2) / (safe + z2)
    half = z / (safe + z2) * np.sqrt(np.maximum(k * (safe - k) / safe, 0.0) + 0.25 * z2)
    lo = np.where(n > 0, np.clip(centre - half, 0.0, 1.0), 0.0)
    hi = np.where(n > 0, np.clip(centre + half, 0.0, 1.0), 1.0)
    return lo, hi


def _status_codes(k, n, bound, z, sense) -> np.ndarray:
    lo, hi = wilson(k, n, z)
    bound = np.asarray(bound, np.float64)
    sense = np.asarray(sense)
    ge = sense == ">="
    met = np.where(ge, lo >= bound, hi <= bound)
    missed = np.where(ge, hi < bound, lo > bound)
    return np.where(met, _MET, np.where(missed, _MISSED, _AT))


def constraint_status(k: np.ndarray | int, n: np.ndarray | int, bound: float | np.ndarray,
                      z: float, sense: str = ">=") -> str | np.ndarray:  # fmt: skip
    """Whether the share constraint ``share >= bound`` (or ``<=`` with ``sense="<="``)
    holds, from k successes in n trials and the Wilson interval at quantile ``z``:
    "met" when the whole interval lies on the allowed side (for ``>=``: lower ≥ bound),
    "missed" when the whole interval lies on the other side (for ``>=``: upper < bound),
    "at its bound" otherwise. Arrays broadcast; a scalar answer is a str."""
    if np.any((np.asarray(sense) != ">=") & (np.asarray(sense) != "<=")):
        raise ValueError(f"constraint_status: sense must be '>=' or '<=', not {sense!r}")
    codes = _status_codes(k, n, bound, z, sense)
    out = np.asarray(STATUSES, dtype=object)[codes]
    return str(out) if np.ndim(out) == 0 else out


# ---------------------------------------------------------------- paired differences


def paired(values_a: np.ndarray, values_b: np.ndarray,
           axis: int = 0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Mean and standard error of the paired difference a − b on common samples along
    ``axis``: mean(d) and std(d, ddof=1)/√n. Pass per-sample values, or per-replication
    means (one value per replication of R samples each) for the replication SE."""
    a = np.asarray(values_a, np.float64)
    b = np.asarray(values_b, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired: shapes differ, {a.shape} and {b.shape}")
    n = a.shape[axis]
    if n < 2:
        raise ValueError("paired: need at least 2 common samples")
    d = a - b
    return d.mean(axis=axis), d.std(axis=axis, ddof=1) / math.sqrt(n)


# ---------------------------------------------------------------- the race


class Stage(NamedTuple):
    """One stage of a race: its number (0-based) and the samples [start, stop) of the
    validation stream it draws (the same for every candidate it scores)."""

    index: int
    start: int
    stop: int

    @property
    def size(self) -> int:
        return self.stop - self.start


class Draw(NamedTuple):
    """What ``sample_fn`` returns for a stage (a bare array stands for ``Draw(values)``).

    ``values`` (C_active, n_stage, m): per candidate and sample, each objective's value
    in its own units. ``successes`` (C_active, n_con): for each share constraint, the
    successes counted on this stage's samples; ``trials`` the trials behind them
    (scalar or (C_active, n_con); default n_stage, one trial per sample)."""

    values: np.ndarray
    successes: np.ndarray | None = None
    trials: np.ndarray | int | None = None


@dataclass(frozen=True)
class RaceResult:
    """The race's answer. Per candidate (in the order given): ``n_samples`` used,
    ``mean``/``se`` (C, m) of each objective in its own units, ``diff``/``diff_se`` (C, m)
    the paired difference candidate − best on their common samples (own units; 0 for the
    best), ``share``/``share_lo``/``share_hi``/``status`` (C, n_con) each constraint's
    share, its Wilson interval at quantile ``z`` and its status, ``verdict`` (C,) "best" |
    "equivalent" | "worse", ``why`` (C,) why a candidate is worse ("margin",
    "dominated", "constraint") or "", ``settled`` (C,) for a remaining candidate whether
    its equivalence to its group's head was shown (for a head: whether every pair with
    another remaining candidate was decided); False for the eliminated. The summary: ``best`` (the leader),
    ``tied`` (the remaining candidates, the best first), ``summary`` ("one
    recommendation", "a tied set of K layouts", "a front of K layouts"), ``reason``
    ("one left", "decided", "cap"), ``n_stages``, ``alpha`` and ``margin``."""

    n_samples: np.ndarray
    mean: np.ndarray
    se: np.ndarray
    diff: np.ndarray
    diff_se: np.ndarray
    share: np.ndarray
    share_lo: np.ndarray
    share_hi: np.ndarray
    status: np.ndarray
    verdict: np.ndarray
    why: np.ndarray
    settled: np.ndarray
    best: int
    tied: tuple[int, ...]
    summary: str
    reason: str
    n_stages: int
    z: float
    alpha: float
    margin: np.ndarray

    @property
    def decided(self) -> bool:
        """True when the race ended with every remaining pair and constraint decided."""
        return self.reason != "cap"


def _as_draw(out, n_act: int, size: int) -> Draw:
    if isinstance(out, Draw):
        d = out
    elif isinstance(out, tuple):
        d = Draw(*out)
    else:
        d = Draw(out)
    v = np.asarray(d.values, np.float64)
    if v.ndim == 2:
        v = v[..., None]
    if v.ndim != 3 or v.shape[:2] != (n_act, size):
        raise ValueError(f"race: sample_fn must return values of shape ({n_act}, {size}, m), "
                         f"not {np.shape(d.values)}")  # fmt: skip
    bad = ~np.isfinite(v).all(axis=(1, 2))
    if bad.any():
        raise ValueError(f"race: sample_fn returned non-finite values for {int(bad.sum())} of "
                         f"{n_act} candidates")  # fmt: skip
    s = t = None
    if d.successes is not None:
        s = np.asarray(d.successes, np.float64)
        if s.ndim == 1:
            s = s[:, None]
        t = np.broadcast_to(np.asarray(size if d.trials is None else d.trials, np.float64),
                            s.shape)  # fmt: skip
        if s.shape[0] != n_act or np.any(s < 0) or np.any(s > t):
            raise ValueError("race: successes must be (C_active, n_con) with 0 ≤ successes ≤ "
                             "trials")  # fmt: skip
    return Draw(v, s, t)


def _pair_stats(act, nS, Sx, Sxx, shift):
    """Paired differences of every pair on its common stages: (D, SE, N), D[i, j, k] the
    mean of x_i − x_j on objective k. ``act`` (C, S) who was sampled at each stage, ``nS``
    (S,) the stage sizes, ``Sx`` (C, S, m) and ``Sxx`` (C, C, S, m) the stage sums of the
    shifted values and of their products."""
    w = act[:, None, :] & act[None, :, :]  # (C, C, S): stages both have
    wf = w.astype(np.float64)
    N = wf @ nS  # (C, C)
    si = np.einsum("ijs,isk->ijk", wf, Sx)  # Σ x_i over the common stages
    diag = np.einsum("iisk->isk", Sxx)
    qi = np.einsum("ijs,isk->ijk", wf, diag)  # Σ x_i²
    cross = np.einsum("ijs,ijsk->ijk", wf, Sxx)  # Σ x_i x_j
    Nn = np.maximum(N, 1.0)[..., None]
    dm = (si - si.transpose(1, 0, 2)) / Nn  # mean of shifted differences
    ss = qi + qi.transpose(1, 0, 2) - 2.0 * cross  # Σ d²
    var = np.maximum(ss - Nn * dm**2, 0.0) / np.maximum(Nn - 1.0, 1.0)
    D = dm + (shift[:, None, :] - shift[None, :, :])
    SE = np.sqrt(var / Nn)
    return D, SE, N


def _sf_margin(num: np.ndarray, se: np.ndarray, df: np.ndarray | None = None) -> np.ndarray:
    """P(Z > num/se), or P(T_df > num/se) with ``df`` (broadcast with num); se = 0 gives 0
    when num > 0 and 1 otherwise."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, num / np.where(se > 0, se, 1.0), np.where(num > 0, np.inf, -np.inf))
    return norm_sf(t) if df is None else t_sf(t, df)


def race(sample_fn: Callable[[np.ndarray, Stage], object], n_candidates: int, *,
         margin: float | Sequence[float], max_samples: int, stage: int = 64,
         alpha: float = 0.05, maximize: bool | Sequence[bool] = False, primary: int = 0,
         bound: float | Sequence[float] | None = None,
         sense: str | Sequence[str] = ">=", student: bool = False,
         first: int | None = None) -> RaceResult:  # fmt: skip
    """Race ``n_candidates`` candidates on fresh samples (the module docstring gives the
    rules) and return a :class:`RaceResult`.

    ``sample_fn(active, stage)`` scores the candidates ``active`` (int array, ascending)
    on the samples ``stage.start`` to ``stage.stop`` of the validation stream and returns
    a :class:`Draw` (or the bare values array): values (len(active), stage.size, m) and,
    when the study has share constraints, their success counts. ``margin``: the
    equivalence margin δ of each objective (one number for all, or m numbers, > 0).
    ``max_samples``: the cap per candidate; ``stage``: samples per stage (the first stage
    draws min(stage, max_samples) ≥ 2). ``alpha``: the family-wise error of all the
    race's decisions. ``maximize``: which objectives are better larger (one bool or m).
    ``primary``: the objective that picks the leader. ``bound``/``sense``: each share
    constraint's bound and its side (``">="``: share ≥ bound). ``student``: the values
    are per-unit means (one replication of many samples each, a handful of units): the
    tests use Student's t with N − 1 degrees of freedom, N the pair's common units,
    instead of the normal approximation. ``first``: the first stage's size (default
    ``stage``; e.g. ``first=2, stage=1`` for replications, as a paired SE needs two)."""
    C = int(n_candidates)
    if C < 1:
        raise ValueError("race: need at least one candidate")
    max_samples, stage = int(max_samples), int(stage)
    first = stage if first is None else int(first)
    if stage < 1 or min(first, max_samples) < 2:
        raise ValueError("race: the first stage needs at least 2 samples")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"race: alpha must lie in (0, 1), not {alpha}")
    n_looks = 1 + math.ceil(max(max_samples - first, 0) / stage)
    a_look = alpha / n_looks
    z = norm_ppf(1.0 - a_look / 2.0)

    n = np.zeros(C, np.int64)
    live = np.ones(C, bool)  # not eliminated
    sampled = np.ones(C, bool)  # gets the next stage's samples
    why = np.full(C, "", dtype=object)
    eq = np.zeros((C, C), bool)  # pairs shown equivalent (final once shown)
    apart = np.zeros((C, C), bool)  # pairs shown to be a trade-off (several objectives)
    acts: list[np.ndarray] = []
    sizes: list[int] = []
    sx: list[np.ndarray] = []
    sxx: list[np.ndarray] = []
    shift = sign = delta = None
    succ = trials = None
    bnd = sns = None
    m = n_con = 0
    reason = "cap"
    s = 0
    codes = np.zeros((C, 0), np.int64)
    D = SE = None
    while True:
        idx = np.flatnonzero(sampled)
        start = int(n[idx[0]])
        size = min(first if s == 0 else stage, max_samples - start)
        st = Stage(s, start, start + size)
        draw = _as_draw(sample_fn(idx.copy(), st), idx.size, size)
        if s == 0:
            m = draw.values.shape[2]
            sign = np.where(np.broadcast_to(np.asarray(maximize, bool), (m,)), -1.0, 1.0)
            delta = np.broadcast_to(np.asarray(margin, np.float64), (m,)).copy()
            if not (np.all(np.isfinite(delta)) and np.all(delta > 0)):
                raise ValueError(f"race: every margin must be a finite number > 0, not {margin}")
            if not 0 <= primary < m:
                raise ValueError(f"race: primary objective {primary} not in 0..{m - 1}")
            shift = np.zeros((C, m))
            shift[idx] = (draw.values * sign).mean(axis=1)
            n_con = 0 if draw.successes is None else draw.successes.shape[1]
            succ, trials = np.zeros((C, n_con)), np.zeros((C, n_con))
            if n_con:
                if bound is None:
                    raise ValueError("race: share counts given without their bounds")
                bnd = np.broadcast_to(np.asarray(bound, np.float64), (n_con,))
                sns = np.broadcast_to(np.asarray(sense), (n_con,))
                if np.any((sns != ">=") & (sns != "<=")):
                    raise ValueError(f"race: sense must be '>=' or '<=', not {sense!r}")
        elif (0 if draw.successes is None else draw.successes.shape[1]) != n_con:
            raise ValueError("race: sample_fn changed the number of share constraints")
        if draw.values.shape[2] != m:
            raise ValueError("race: sample_fn changed the number of objectives")
        V = draw.values * sign - shift[idx][:, None, :]
        x_s = np.zeros((C, m))
        x_s[idx] = V.sum(axis=1)
        xx_s = np.zeros((C, C, m))
        xx_s[np.ix_(idx, idx)] = np.einsum("ink,jnk->ijk", V, V)
        acts.append(sampled.copy())
        sizes.append(size)
        sx.append(x_s)
        sxx.append(xx_s)
        n[idx] += size
        if n_con:
            succ[idx] += draw.successes
            trials[idx] += draw.trials
        s += 1

        act = np.stack(acts, axis=1)
        D, SE, N = _pair_stats(act, np.asarray(sizes, np.float64), np.stack(sx, axis=1),
                               np.stack(sxx, axis=2), shift)  # fmt: skip
        codes = _status_codes(succ, trials, bnd, z, sns) if n_con else np.zeros((C, 0), int)
        dfn = np.maximum(N - 1.0, 1.0) if student else None  # (C, C): the pairs' t df
        missed = (codes == _MISSED).any(axis=1)
        met = (codes == _MET).all(axis=1)
        if (live & ~missed).any():
            out = live & missed
            why[out] = "constraint"
            live &= ~out
        own, own_se = _own_stats(act, np.stack(sx, axis=1), np.stack(sxx, axis=2), shift, n)
        ref_pool = live & met
        if m == 1 and ref_pool.any():
            r = _argbest(own[:, primary], ref_pool)
            cand = np.flatnonzero(live & (np.arange(C) != r))
            p = _sf_margin(D[cand, r, 0] - delta[0], SE[cand, r, 0],
                           None if dfn is None else dfn[cand, r])  # fmt: skip
            out = cand[holm_reject(p, a_look)]
            why[out] = "margin"
            live[out] = False
        elif m > 1 and ref_pool.any():
            jj, ii = np.nonzero(ref_pool[:, None] & live[None, :] & ~np.eye(C, dtype=bool))
            if jj.size:
                d, se = D[ii, jj], SE[ii, jj]  # (P, m): i − j, > 0 where j is better
                df = None if dfn is None else dfn[ii, jj][:, None]
                p_noninf = _sf_margin(d + delta, se, df).max(axis=1)
                p_better = np.minimum(m * _sf_margin(d - delta, se, df).min(axis=1), 1.0)
                rej = holm_reject(np.maximum(p_noninf, p_better), a_look)
                out = np.unique(ii[rej])
                why[out] = "dominated"
                live[out] = False
        und = live[:, None] & live[None, :] & ~eq & ~apart & ~np.eye(C, dtype=bool)
        iu, ju = np.nonzero(np.triu(und))
        if iu.size:
            d, se = D[iu, ju], SE[iu, ju]  # (P, m): i − j
            df = None if dfn is None else dfn[iu, ju][:, None]
            p_eq = np.maximum(_sf_margin(delta - d, se, df),
                              _sf_margin(d + delta, se, df)).max(axis=1)  # fmt: skip
            if m == 1:
                rej = holm_reject(p_eq, a_look)
                eq[iu[rej], ju[rej]] = eq[ju[rej], iu[rej]] = True
            else:  # equivalent, or a trade-off: each better than the other somewhere
                p_i = m * _sf_margin(-d - delta, se, df).min(axis=1)  # i better by > δ somewhere
                p_j = m * _sf_margin(d - delta, se, df).min(axis=1)
                p_tr = np.minimum(np.maximum(p_i, p_j), 1.0)
                rej = holm_reject(np.minimum(2.0 * np.minimum(p_eq, p_tr), 1.0), a_look)
                e, a = rej & (p_eq <= p_tr), rej & (p_eq > p_tr)
                eq[iu[e], ju[e]] = eq[ju[e], iu[e]] = True
                apart[iu[a], ju[a]] = apart[ju[a], iu[a]] = True
        und = live[:, None] & live[None, :] & ~eq & ~apart & ~np.eye(C, dtype=bool)
        at_bound = (codes == _AT).any(axis=1)
        sampled &= live & (und.any(axis=1) | at_bound)
        if live.sum() == 1:
            reason = "one left"
            break
        if not sampled.any():
            reason = "decided"
            break
        if n[sampled].max() >= max_samples:
            reason = "cap"
            break

    return _result(C, n, live, why, eq, apart, codes, succ, trials, z, D, SE, own, own_se, sign,
                   primary, delta, reason, s, alpha)  # fmt: skip


def _own_stats(act, Sx, Sxx, shift, n):
    """Each candidate's mean (internal signs) and its SE, std(ddof=1)/√n, of every
    objective over all its samples."""
    a = act.astype(np.float64)
    tot = np.einsum("is,isk->ik", a, Sx)
    sq = np.einsum("is,iisk->ik", a, Sxx)
    nn = np.maximum(n, 1)[:, None].astype(np.float64)
    dm = tot / nn
    var = np.maximum(sq - nn * dm**2, 0.0) / np.maximum(nn - 1.0, 1.0)
    return dm + shift, np.sqrt(var / nn)


def _argbest(x: np.ndarray, pool: np.ndarray) -> int:
    return int(np.flatnonzero(pool)[np.argmin(x[pool])])


def _result(C, n, live, why, eq, apart, codes, succ, trials, z, D, SE, own, own_se, sign, primary,
            delta, reason, n_stages, alpha) -> RaceResult:  # fmt: skip
    missed = (codes == _MISSED).any(axis=1)
    pool = live & ~missed if (live & ~missed).any() else live
    best = _argbest(own[:, primary], pool)
    verdict = np.where(live, "equivalent", "worse").astype(object)
    settled = np.zeros(C, bool)
    order = [int(i) for i in np.flatnonzero(live)[np.argsort(own[live, primary], kind="stable")]]
    order.remove(best)
    order.insert(0, best)
    heads: list[int] = []
    for i in order:
        head = next((h for h in heads if eq[i, h]), None)
        if head is None:  # not shown apart from a head: the data cannot separate them
            head = next((h for h in heads if not apart[i, h]), None)
        if head is None:
            heads.append(i)
            verdict[i] = "best"
            others = live & (np.arange(C) != i)
            settled[i] = bool(np.all((eq[i] | apart[i])[others]))
        else:
            settled[i] = bool(eq[i, head])
    k = len(order)
    if k == 1:
        summary = "one recommendation"
    elif len(heads) == 1:
        summary = f"a tied set of {k} layouts"
    else:
        summary = f"a front of {k} layouts"
    share = np.where(trials > 0, succ / np.where(trials > 0, trials, 1.0), np.nan)
    lo, hi = wilson(succ, trials, z)
    return RaceResult(
        n_samples=n.copy(),
        mean=own * sign,
        se=own_se,
        diff=D[:, best, :] * sign + 0.0,
        diff_se=SE[:, best, :],
        share=share,
        share_lo=lo,
        share_hi=hi,
        status=np.asarray(STATUSES, dtype=object)[codes],
        verdict=verdict,
        why=why,
        settled=settled,
        best=best,
        tied=tuple(order),
        summary=summary,
        reason=reason,
        n_stages=n_stages,
        z=z,
        alpha=alpha,
        margin=delta * 1.0,
    )


# ---------------------------------------------------------------- how tied layouts differ


def _widths(lo, hi, d: int) -> np.ndarray:
    lo = np.broadcast_to(np.asarray(lo, np.float64), (d,))
    hi = np.broadcast_to(np.asarray(hi, np.float64), (d,))
    if np.any(hi < lo) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("bounds must be finite with every upper bound ≥ its lower bound")
    return np.where(hi > lo, hi - lo, 1.0)


def differing_variables(X_tied: np.ndarray, names: Sequence[str], lo: np.ndarray,
                        hi: np.ndarray, tol: float = 0.02) -> list[str]:  # fmt: skip
    """The variables in which the layouts ``X_tied`` (K, d) differ: those whose range
    over the K layouts, as a share of the box width hi − lo, exceeds ``tol`` (in order of
    ``names``). One layout differs in nothing."""
    X = np.atleast_2d(np.asarray(X_tied, np.float64))
    if X.shape[1] != len(names):
        raise ValueError(f"differing_variables: {X.shape[1]} columns for {len(names)} names")
    spread = (X.max(axis=0) - X.min(axis=0)) / _widths(lo, hi, X.shape[1])
    return [str(nm) for nm, s in zip(names, spread, strict=True) if s > tol]


def mirror(X_a: np.ndarray, X_b: np.ndarray, names: Sequence[str],
           pairs: Sequence[tuple[str, str, float] | tuple[str, str]], *,
           lo: np.ndarray | None = None, hi: np.ndarray | None = None,
           tol: float = 0.02) -> bool:  # fmt: skip
    """Whether layout ``X_b`` is the mirror image of ``X_a`` under a scene symmetry.

    The caller names the symmetry (this module cannot see the scene): ``pairs`` lists
    ``(source, target, sign)`` triples (sign ±1, default +1 for a pair), meaning that the
    mirror image's variable ``target`` is ``sign`` × the layout's ``source``; variables not
    named as a target map to themselves. Examples, for a reflection y → −y of a scene
    symmetric about the x–z plane: a port's lateral coordinate ``("p1_y", "p1_y", -1)``;
    two ports that trade places under it: ``("p1_y", "p2_y", -1), ("p2_y", "p1_y", -1),
    ("p1_x", "p2_x"), ("p2_x", "p1_x")``. The layouts are mirror images when the image of
    ``X_a`` lies within ``tol`` of ``X_b`` (Euclidean, box-normalised by ``lo``/``hi``
    when given, else in the variables' own units). A layout that is its own image (it
    lies on the plane of symmetry) is its own mirror: check that two layouts differ
    (:func:`differing_variables`) before calling them a mirror pair."""
    a = np.asarray(X_a, np.float64).ravel()
    b = np.asarray(X_b, np.float64).ravel()
    names = [str(x) for x in names]
    if a.shape != b.shape or a.size != len(names):
        raise ValueError(f"mirror: layouts of {a.size} and {b.size} values for {len(names)} names")
    where = {nm: i for i, nm in enumerate(names)}
    image = a.copy()
    seen: set[str] = set()
    for p in pairs:
        src, dst, sgn = (*p, 1.0) if len(p) == 2 else p
        if src not in where or dst not in where:
            raise ValueError(f"mirror: unknown variable in the pair {tuple(p)}; known: {names}")
        if dst in seen:
            raise ValueError(f"mirror: variable '{dst}' is the target of two pairs")
        if float(sgn) not in (1.0, -1.0):
            raise ValueError(f"mirror: a pair's sign must be +1 or -1, not {sgn}")
        seen.add(dst)
        image[where[dst]] = float(sgn) * a[where[src]]
    width = np.ones(a.size) if lo is None or hi is None else _widths(lo, hi, a.size)
    return bool(np.linalg.norm((image - b) / width) <= tol)


def tie_note(X_tied: np.ndarray, names: Sequence[str], lo: np.ndarray, hi: np.ndarray,
             pairs: Sequence[tuple] | None = None, labels: Sequence[str] | None = None,
             tol: float = 0.02) -> str:  # fmt: skip
    """One line on how the layouts of a tied set differ: the variables that differ
    (:func:`differing_variables`), and each pair of layouts that are mirror images under
    the caller's symmetry ``pairs`` (:func:`mirror`; none when ``pairs`` is None).
    ``labels`` name the layouts (default: their positions in ``X_tied``)."""
    X = np.atleast_2d(np.asarray(X_tied, np.float64))
    labels = [str(i) for i in range(len(X))] if labels is None else [str(x) for x in labels]
    diff = differing_variables(X, names, lo, hi, tol)
    if not diff:
        return "the tied layouts do not differ"
    text = "the tied layouts differ in " + ", ".join(diff)
    if pairs:
        mirrored = [f"{labels[i]} and {labels[j]}" for i in range(len(X)) for j in range(i + 1, len(X))
                    if differing_variables(X[[i, j]], names, lo, hi, tol)
                    and mirror(X[i], X[j], names, pairs, lo=lo, hi=hi, tol=tol)]  # fmt: skip
        if mirrored:
            text += "; mirror images: " + "; ".join(mirrored)
    return text
