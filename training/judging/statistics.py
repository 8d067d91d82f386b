"""Interval estimates for ``proteo eval`` and the benchmarks: the one home of interval code.

Every interval here is two-sided at 95 % unless ``confidence`` says otherwise, and every
function is deterministic: the bootstraps draw from ``numpy.random.default_rng(seed)`` with a
fixed default ``seed``, so that a published table is reproduced exactly from its episodes.

One run (one policy, or one checkpoint, over ``n`` episodes):

- :func:`wilson`: the Wilson score interval of a success rate ``k / n``
  (``scipy.stats.binomtest(k, n).proportion_ci(method="wilson")``);
- :func:`mean_ci`: a mean and the half-width of its Student t interval
  (``scipy.stats.t.ppf``), for returns and cycles to success.

A controller against a reference on the same worlds: :func:`paired_difference`, the mean
difference of a per-episode measure over the pairs (training seed, world) that a mask keeps,
with a bootstrap that draws training seeds and worlds jointly (each resample draws the seeds
with replacement and the worlds with replacement, and every drawn seed plays every drawn
world, as the seeds did), its percentile interval, and the bootstrap's two-sided p-value;
:func:`equivalence`, two one-sided tests that the difference lies within a fixed margin.

A group of training seeds (one configuration trained with several seeds, each run evaluated on
its episodes): :func:`group_bootstrap`, a stratified two-level bootstrap. Each resample draws
the training seeds with replacement, then, within each drawn seed, that seed's episodes with
replacement; the percentile interval of the pooled statistic over the resamples is the
interval. It covers both sources of spread: a new training seed, and new episodes.

Across tasks, following the definitions of rliable (Agarwal et al., "Deep reinforcement
learning at the edge of the statistical precipice", NeurIPS 2021), on an array of normalised
scores of shape ``(runs, tasks)`` (:func:`normalized_score`):

- :func:`iqm` / :func:`iqm_ci`: the interquartile mean over all runs x tasks
  (``scipy.stats.trim_mean(x, 0.25)``), with a stratified bootstrap interval (runs resampled
  within each task);
- :func:`probability_of_improvement` / :func:`probability_of_improvement_ci`: P(X > Y), the
  Mann-Whitney U statistic over ``n * m`` with ties counted half, per task, averaged over tasks;
- :func:`performance_profile`: the fraction of runs x tasks whose score exceeds each ``tau``,
  with bootstrap bands.

A task whose normalised score is undefined (the rules do no better or worse than random:
``rules_rate == random_rate``) has NaN scores; the across-task functions leave such a task
out (a task column that is NaN in any run is dropped), and raise ``ValueError`` when no task
is left.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

DEFAULT_RESAMPLES = 2000
"""Bootstrap resamples unless a caller asks for another number."""

DEFAULT_SEED = 0
"""The generator seed of every bootstrap (published tables are reproducible)."""


# --------------------------------------------------------------------------- one run
def t_quantile(df: float, confidence: float = 0.95) -> float:
    """The two-sided Student t quantile ``t_{(1 + confidence) / 2, df}`` (``nan`` for ``df < 1``);
    ``t_quantile(31) = 2.0395``."""
    from scipy.stats import t

    if not df >= 1:
        return float("nan")
    return float(t.ppf((1.0 + confidence) / 2.0, df))


def mean_ci(values, confidence: float = 0.95) -> tuple[float, float]:
    """``(mean, half-width)`` of the Student t interval of the mean of ``values`` (1-D).

    ``(nan, nan)`` for no values; ``(value, nan)`` for one.
    """
    v = np.asarray(values, dtype=float).ravel()
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size == 1:
        return float(v[0]), float("nan")
    return float(v.mean()), t_quantile(v.size - 1, confidence) * float(v.std(ddof=1)) / math.sqrt(v.size)


def new_seed_interval(rates, confidence: float = 0.95, bounds=(0.0, 1.0)) -> tuple[float, float, float]:
    """``(mean, low, high)``: where one more training seed's measure on the same worlds is
    expected to land, from ``rates`` (the measure of each training seed, 1-D; by default success
    rates): the Student t prediction interval ``mean +- t_{n-1} * s * sqrt(1 + 1/n)``, clipped to
    ``bounds`` (``(0, inf)`` for cycles; ``(mean, nan, nan)`` below two seeds).

    The interval of a recipe's pooled success is about the mean of its seeds and narrows as seeds
    are added; a rerun with one new seed varies as the seeds do, so this is the interval that
    rerun should land in. ``new_seed_interval([0.8, 0.9, 1.0]) = (0.9, 0.40, 1.0)``.
    """
    v = np.asarray(rates, dtype=float).ravel()
    mean = float(v.mean()) if v.size else float("nan")
    if v.size < 2:
        return mean, float("nan"), float("nan")
    half = t_quantile(v.size - 1, confidence) * float(v.std(ddof=1)) * math.sqrt(1.0 + 1.0 / v.size)
    return mean, max(bounds[0], mean - half), min(bounds[1], mean + half)


def wilson(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """``(low, high)``: the Wilson score interval of the proportion ``successes / n``
    (``(nan, nan)`` when ``n == 0``); ``wilson(24, 30) = (0.627, 0.905)``."""
    from scipy.stats import binomtest

    if n <= 0:
        return float("nan"), float("nan")
    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


# --------------------------------------------------------------------------- a group of training seeds
def _padded(per_seed: Sequence, dtype) -> np.ndarray:
    """The ragged per-seed episodes as one ``(seeds, max episodes)`` array (zeros past the end)."""
    out = np.zeros((len(per_seed), max(len(x) for x in per_seed)), dtype=dtype)
    for i, x in enumerate(per_seed):
        out[i, : len(x)] = np.asarray(x, dtype=dtype)
    return out


def _percentiles(samples: np.ndarray, confidence: float) -> tuple[float, float]:
    """The percentile interval of the finite ``samples`` (``(nan, nan)`` when there are none)."""
    s = samples[np.isfinite(samples)]
    if s.size == 0:
        return float("nan"), float("nan")
    lo, hi = np.percentile(s, [50.0 * (1.0 - confidence), 50.0 * (1.0 + confidence)])
    return float(lo), float(hi)


def group_bootstrap(
    successes: Sequence,
    cycles: Sequence,
    returns: Sequence | None = None,
    *,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    confidence: float = 0.95,
) -> dict:
    """The pooled measures of a group of training seeds, with stratified-bootstrap intervals.

    Args:
        successes: one 1-D sequence of booleans per training seed: the success of each of its
            episodes (seeds may have different numbers of episodes, each at least one).
        cycles: the same shape: the cycles each episode ran (the cycle of success where it
            succeeded).
        returns: optional, the same shape: the return of each episode.
        resamples: bootstrap resamples; seed: the generator's seed; confidence: the level.

    Returns:
        ``{"success_rate", "success_lo", "success_hi", "cycles_to_success", "cycles_lo",
        "cycles_hi", "return_mean", "return_lo", "return_hi"}`` (floats). The point estimates
        are pooled over every episode of the group: the success rate is successes over episodes,
        cycles to success the mean over the successful episodes (``nan`` when none), the return
        the mean over episodes (``nan`` without ``returns``). Each interval is the percentile
        interval of the same statistic over ``resamples`` two-level resamples (training seeds
        with replacement, then each drawn seed's episodes with replacement); a resample without
        a successful episode has no cycles to success and is left out of that interval, which is
        ``nan`` with fewer than two successful episodes in the group.
    """
    if len(successes) == 0 or len(cycles) != len(successes) or any(len(x) == 0 for x in successes):
        raise ValueError("group_bootstrap: one non-empty sequence of episodes per training seed is needed")
    if [len(x) for x in cycles] != [len(x) for x in successes] or (
        returns is not None and [len(x) for x in returns] != [len(x) for x in successes]
    ):
        raise ValueError("group_bootstrap: successes, cycles and returns must have the same shape")
    n_seeds = len(successes)
    counts = np.array([len(x) for x in successes])
    won = _padded(successes, bool)
    cyc = _padded(cycles, float)
    ret = _padded(returns, float) if returns is not None else None

    rng = np.random.default_rng(seed)
    picked = rng.integers(0, n_seeds, size=(resamples, n_seeds))  # training seeds drawn
    width = counts.max()
    n_picked = counts[picked]  # (B, S): episodes of each drawn seed
    episode = np.floor(rng.random((resamples, n_seeds, width)) * n_picked[..., None]).astype(np.int64)
    inside = np.arange(width)[None, None, :] < n_picked[..., None]  # (B, S, W): real episodes
    rows = picked[..., None]
    w = won[rows, episode] & inside
    episodes = inside.sum(axis=(1, 2))
    wins = w.sum(axis=(1, 2))
    rate_b = wins / episodes
    with np.errstate(invalid="ignore", divide="ignore"):
        cycles_b = np.where(w, cyc[rows, episode], 0.0).sum(axis=(1, 2)) / wins
    all_won = np.concatenate([np.asarray(x, dtype=bool) for x in successes])
    all_cycles = np.concatenate([np.asarray(x, dtype=float) for x in cycles])
    n_won = int(all_won.sum())
    out = {
        "success_rate": float(all_won.mean()),
        "cycles_to_success": float(all_cycles[all_won].mean()) if n_won else float("nan"),
        "return_mean": float("nan"),
        "return_lo": float("nan"),
        "return_hi": float("nan"),
    }
    out["success_lo"], out["success_hi"] = _percentiles(rate_b, confidence)
    out["cycles_lo"], out["cycles_hi"] = (
        _percentiles(cycles_b, confidence) if n_won >= 2 else (float("nan"), float("nan"))
    )
    if ret is not None:
        return_b = np.where(inside, ret[rows, episode], 0.0).sum(axis=(1, 2)) / episodes
        out["return_mean"] = float(np.concatenate([np.asarray(x, dtype=float) for x in returns]).mean())
        out["return_lo"], out["return_hi"] = _percentiles(return_b, confidence)
    return out


# --------------------------------------------------------------------------- across tasks
def normalized_score(rate, random_rate, rules_rate) -> np.ndarray:
    """``(rate - random_rate) / (rules_rate - random_rate)``, broadcast (NumPy rules): 0 is the
    random policy, 1 the hand-coded rules. Where ``rules_rate == random_rate`` the task has no
    scale and the score is NaN (the across-task functions leave that task out).

    Typically ``rate`` has shape ``(runs, tasks)`` (each training seed's success rate per task)
    and ``random_rate``, ``rules_rate`` shape ``(tasks,)``.
    """
    rate, lo, hi = (np.asarray(x, dtype=float) for x in (rate, random_rate, rules_rate))
    scale = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(scale != 0, (rate - lo) / np.where(scale != 0, scale, 1.0), np.nan)


def _tasks(scores, name: str = "scores") -> np.ndarray:
    """``scores`` as a ``(runs, tasks)`` float array without the tasks that have a NaN."""
    s = np.asarray(scores, dtype=float)
    if s.ndim == 1:
        s = s[:, None]
    if s.ndim != 2 or s.shape[0] == 0:
        raise ValueError(f"{name}: an array of shape (runs, tasks) with at least one run is needed; got {s.shape}")
    s = s[:, ~np.isnan(s).any(axis=0)]
    if s.shape[1] == 0:
        raise ValueError(f"{name}: no task with a defined normalised score (rules == random on every task)")
    return s


def _resample_runs(scores: np.ndarray, rng, resamples: int, joint: bool = False) -> np.ndarray:
    """``(resamples, runs, tasks)``: each task's runs drawn with replacement, independently per
    task, or with ``joint`` the same runs for every task (when the tasks are splits that share
    each run's checkpoint, so that a run's scores on them are not independent)."""
    runs, tasks = scores.shape
    idx = rng.integers(0, runs, size=(resamples, runs, 1 if joint else tasks))
    idx = np.broadcast_to(idx, (resamples, runs, tasks))
    return np.take_along_axis(np.broadcast_to(scores, (resamples, runs, tasks)), idx, axis=1)


def iqm(scores) -> float:
    """The interquartile mean of ``scores`` (shape ``(runs, tasks)``) over all runs x tasks:
    ``scipy.stats.trim_mean(scores.ravel(), 0.25)`` (the middle 50 %)."""
    from scipy.stats import trim_mean

    return float(trim_mean(_tasks(scores).ravel(), 0.25))


def iqm_ci(
    scores,
    *,
    joint: bool = False,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    confidence: float = 0.95,
) -> tuple[float, float, float]:
    """``(iqm, low, high)``: :func:`iqm` and its stratified-bootstrap percentile interval (each
    task's runs resampled with replacement; with ``joint`` whole runs, see :func:`_resample_runs`)."""
    from scipy.stats import trim_mean

    s = _tasks(scores)
    boot = _resample_runs(s, np.random.default_rng(seed), resamples, joint).reshape(resamples, -1)
    lo, hi = _percentiles(trim_mean(boot, 0.25, axis=1), confidence)
    return iqm(s), lo, hi


def paired_difference(
    x,
    reference,
    keep=None,
    *,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    confidence: float = 0.95,
) -> dict:
    """How much a controller's per-episode measure exceeds a reference's on the same worlds.

    Args:
        x: ``(training seeds, worlds)``: the controller's measure on each world, each training
            seed on the same worlds (success as 0/1, cycles, ...).
        reference: ``(worlds,)``: the reference's measure on those worlds, in the same order.
        keep: optional ``(training seeds, worlds)`` booleans: the pairs that count (for example
            the worlds where both succeeded, to compare cycles); every pair without it.
        resamples: bootstrap resamples; seed: the generator's seed; confidence: the level.

    Returns:
        ``{"difference", "lo", "hi", "p", "pairs"}``: the mean of ``x - reference`` over the kept
        pairs, the percentile interval of that mean over ``resamples`` joint resamples (training
        seeds and worlds drawn with replacement; a resample without a kept pair is left out),
        the two-sided bootstrap p-value ``min(1, 2 min(P(d* <= 0), P(d* >= 0)))`` of "no
        difference", and the number of kept pairs. ``nan`` everywhere without a kept pair.
    """
    xs = np.asarray(x, dtype=float)
    ref = np.asarray(reference, dtype=float)
    if xs.ndim != 2 or ref.shape != xs.shape[1:] or xs.size == 0:
        raise ValueError(
            f"paired_difference: x of shape (training seeds, worlds) and a reference of shape (worlds,) are "
            f"needed; got {xs.shape} and {ref.shape}"
        )
    mask = np.ones(xs.shape, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    if mask.shape != xs.shape:
        raise ValueError(f"paired_difference: keep has shape {mask.shape}, x {xs.shape}")
    delta = np.where(mask, xs - ref[None, :], 0.0)
    pairs = int(mask.sum())
    if pairs == 0:
        return {"difference": float("nan"), "lo": float("nan"), "hi": float("nan"), "p": float("nan"), "pairs": 0}
    rng = np.random.default_rng(seed)
    n_seeds, n_worlds = xs.shape
    seeds = rng.integers(0, n_seeds, size=(resamples, n_seeds))[:, :, None]
    worlds = rng.integers(0, n_worlds, size=(resamples, n_worlds))[:, None, :]
    kept = mask[seeds, worlds].sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        samples = delta[seeds, worlds].sum(axis=(1, 2)) / kept
    samples = samples[kept > 0]
    lo, hi = _percentiles(samples, confidence)
    p = min(1.0, 2.0 * min(float((samples <= 0).mean()), float((samples >= 0).mean())))
    return {"difference": float(delta.sum() / pairs), "lo": lo, "hi": hi, "p": p, "pairs": pairs}


def equivalence(
    x,
    reference,
    margin: float,
    keep=None,
    *,
    alpha: float = 0.05,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> dict:
    """Two one-sided tests (TOST) of "the controller's measure is within ``margin`` of the reference's".

    Each one-sided test at level ``alpha`` rejects "the difference is at most ``-margin``" and
    "at least ``+margin``"; together they do exactly when the ``1 - 2 alpha`` (90 %) interval of
    :func:`paired_difference` (the same joint bootstrap over training seeds and worlds) lies
    inside ``(-margin, +margin)``. "Not detectably different" is not this: a wide interval around
    0 is neither.

    Returns:
        :func:`paired_difference`'s ``{"difference", "lo", "hi", "p", "pairs"}`` at ``1 - 2 alpha``,
        with ``"margin"`` and ``"equivalent"`` (both one-sided tests reject; never without a pair).
    """
    if not 0.0 < margin:
        raise ValueError(f"equivalence: margin={margin!r} is not allowed; allowed: a number > 0")
    d = paired_difference(x, reference, keep, resamples=resamples, seed=seed, confidence=1.0 - 2.0 * alpha)
    return {**d, "margin": margin, "equivalent": bool(d["pairs"]) and -margin < d["lo"] and d["hi"] < margin}


def _improvement(x: np.ndarray, y: np.ndarray, ties: float = 0.5) -> np.ndarray:
    """P(X > Y) + ``ties`` P(X == Y) per task, over the leading axes ``(..., n, tasks)`` and
    ``(..., m, tasks)``: shape ``(..., tasks)``."""
    a, b = x[..., :, None, :], y[..., None, :, :]
    return (a > b).mean(axis=(-3, -2)) + ties * (a == b).mean(axis=(-3, -2))


def probability_of_improvement(x, y, *, ties: float = 0.5) -> float:
    """P(X > Y): the probability that a run of ``x`` beats a run of ``y`` on a task, averaged
    over tasks. ``x`` has shape ``(n, tasks)``, ``y`` ``(m, tasks)`` (the same tasks); per task
    it is the Mann-Whitney U statistic over ``n * m`` with ties counted ``ties`` (a half, as
    rliable does; 0 for the strict probability, and the difference of the two is P(X == Y)). A
    task with a NaN score in either is left out. 1: every run of ``x`` beats every run of ``y``;
    0.5: no difference."""
    xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    xs, ys = (s[:, None] if s.ndim == 1 else s for s in (xs, ys))
    if xs.shape[1:] != ys.shape[1:]:
        raise ValueError(f"probability_of_improvement: x has {xs.shape[1]} tasks, y {ys.shape[1]}")
    keep = ~(np.isnan(xs).any(axis=0) | np.isnan(ys).any(axis=0))
    xs, ys = _tasks(xs[:, keep], "x"), _tasks(ys[:, keep], "y")
    return float(_improvement(xs, ys, ties).mean())


def probability_of_improvement_ci(
    x,
    y,
    *,
    ties: float = 0.5,
    joint: bool = False,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    confidence: float = 0.95,
) -> tuple[float, float, float]:
    """``(P(X > Y), low, high)``: :func:`probability_of_improvement` (ties counted ``ties``) and
    its stratified-bootstrap percentile interval (the runs of ``x`` and of ``y`` resampled within
    each task; with ``joint`` whole runs, see :func:`_resample_runs`)."""
    xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    xs, ys = (s[:, None] if s.ndim == 1 else s for s in (xs, ys))
    point = probability_of_improvement(xs, ys, ties=ties)
    keep = ~(np.isnan(xs).any(axis=0) | np.isnan(ys).any(axis=0))
    xs, ys = xs[:, keep], ys[:, keep]
    rng = np.random.default_rng(seed)
    bx, by = _resample_runs(xs, rng, resamples, joint), _resample_runs(ys, rng, resamples, joint)
    lo, hi = _percentiles(_improvement(bx, by, ties).mean(axis=-1), confidence)
    return point, lo, hi


def performance_profile(
    scores,
    taus,
    *,
    joint: bool = False,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    confidence: float = 0.95,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The score distribution: for each ``tau`` of ``taus`` (1-D), the fraction of runs x tasks
    of ``scores`` (shape ``(runs, tasks)``) whose score exceeds ``tau``, with its bootstrap band.

    Returns:
        ``(profile, low, high)``, each of shape ``(len(taus),)``: the fractions, and the pointwise
        percentile band over stratified resamples (each task's runs resampled with replacement;
        with ``joint`` whole runs, see :func:`_resample_runs`).
    """
    s = _tasks(scores)
    t = np.asarray(taus, dtype=float).ravel()
    profile = (s.ravel()[None, :] > t[:, None]).mean(axis=1)
    boot = _resample_runs(s, np.random.default_rng(seed), resamples, joint).reshape(resamples, -1)
    fractions = (boot[:, None, :] > t[None, :, None]).mean(axis=2)  # (resamples, taus)
    lo, hi = np.percentile(fractions, [50.0 * (1.0 - confidence), 50.0 * (1.0 + confidence)], axis=0)
    return profile, lo, hi
