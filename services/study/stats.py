"""The statistics of a study's report: descriptives, paired tests, Holm's correction.

- **Descriptives** over participants: median and interquartile range (numpy's linear
  quantiles), mean and sample standard deviation. The participant is the unit of
  analysis: each contributes one value per condition and task (the mean of its measured
  trials), so a participant with more trials does not weigh more.
- **Paired test**: the Wilcoxon signed-rank test (:func:`scipy.stats.wilcoxon`,
  two-sided, zero differences dropped as Wilcoxon did: ``zero_method="wilcox"``) on the
  per-participant values of two conditions. It assumes no normal distribution, which
  completion times, counts and questionnaire scores of a handful of people do not have.
- **Effect size**: the matched-pairs rank-biserial correlation (Kerby 2014),
  ``r = (T+ - T-) / (T+ + T-)``, with ``T+`` and ``T-`` the sums of the ranks of the
  positive and negative differences ``a - b``: from -1 (every participant lower under
  ``a``) to 1 (every one higher). Unlike ``Z / sqrt(N)`` it needs no normal
  approximation, so it is defined for the small samples an exact test is run on.
- **Holm's correction** (Holm 1979) over a family of tests: sort the ``m`` p-values,
  multiply the ``i``-th smallest (from 1) by ``m - i + 1``, make the sequence
  non-decreasing by a running maximum, cap at 1. It holds the family-wise error rate at
  alpha without assuming independence, and rejects at least what Bonferroni does.

With few participants a test may be impossible (fewer than two pairs, or no pair that
differs) or unable to reach alpha whatever the data (the exact test's smallest two-sided
p with ``n`` differing pairs is ``2 / 2**n``: 0.0625 for 5); the result says so in
``note`` instead of failing. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import stats as sps


def describe(xs: Sequence[float | None]) -> dict[str, Any]:
    """``n``, ``median``, ``q1``, ``q3``, ``mean``, ``sd`` of the finite values of ``xs``
    (None where there are none; ``sd`` None for fewer than two)."""
    v = np.array([x for x in xs if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return {"n": 0, "median": None, "q1": None, "q3": None, "mean": None, "sd": None}
    q1, med, q3 = (float(q) for q in np.quantile(v, [0.25, 0.5, 0.75]))
    return {"n": int(v.size), "median": med, "q1": q1, "q3": q3, "mean": float(v.mean()),
            "sd": float(v.std(ddof=1)) if v.size > 1 else None}


def holm(pvalues: Sequence[float | None]) -> list[float | None]:
    """Holm-adjusted p-values in the order given (None stays None and is not part of
    the family): reject where the adjusted p is at most alpha."""
    idx = [i for i, p in enumerate(pvalues) if p is not None]
    m = len(idx)
    out: list[float | None] = [None] * len(pvalues)
    running = 0.0
    for rank, i in enumerate(sorted(idx, key=lambda i: float(pvalues[i]))):  # type: ignore[arg-type]
        running = max(running, min(1.0, (m - rank) * float(pvalues[i])))  # type: ignore[arg-type]
        out[i] = running
    return out


def rank_biserial(d: Sequence[float]) -> float | None:
    """The matched-pairs rank-biserial correlation of the differences ``d`` (zeros
    dropped; None when none is left)."""
    v = np.array([x for x in d if x != 0.0], dtype=float)
    if v.size == 0:
        return None
    ranks = sps.rankdata(np.abs(v))
    plus, minus = float(ranks[v > 0].sum()), float(ranks[v < 0].sum())
    return (plus - minus) / (plus + minus)


def paired_test(a: Sequence[float | None], b: Sequence[float | None], alpha: float = 0.05) -> dict[str, Any]:
    """The Wilcoxon signed-rank test of ``a`` against ``b`` (values of the same
    participants, in the same order; a pair with a missing value is left out).

    Returns ``n`` (pairs), ``n_differing``, ``median_difference`` (of ``a - b``),
    ``statistic`` (scipy's: the smaller rank sum), ``p`` (None when not possible),
    ``r_rank_biserial`` and ``note`` (why no test, or why it cannot reach ``alpha``;
    empty otherwise)."""
    pairs = [(x, y) for x, y in zip(a, b, strict=True)
             if x is not None and y is not None and math.isfinite(x) and math.isfinite(y)]
    d = [x - y for x, y in pairs]
    nz = [x for x in d if x != 0.0]
    out: dict[str, Any] = {"n": len(pairs), "n_differing": len(nz),
                           "median_difference": float(np.median(d)) if d else None,
                           "statistic": None, "p": None, "r_rank_biserial": rank_biserial(d), "note": ""}
    if len(pairs) < 2:
        out["note"] = f"not possible: {len(pairs)} participant{'s' * (len(pairs) != 1)} with both values"
        return out
    if not nz:
        out["note"] = "not possible: no participant differs between the two"
        return out
    res = sps.wilcoxon(d, zero_method="wilcox", alternative="two-sided")
    out["statistic"], out["p"] = float(res.statistic), float(res.pvalue)
    floor = 2.0 / 2 ** len(nz)
    if floor > alpha:
        out["note"] = (f"underpowered: with {len(nz)} differing pairs the smallest possible p is "
                       f"{floor:.3g} > alpha {alpha:g}")
    return out
