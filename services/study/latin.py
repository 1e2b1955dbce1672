"""Counterbalancing by a balanced Latin square (Williams 1949).

A Latin square of ``n`` conditions gives each condition once in every row (a
participant's order) and once in every position over the rows. A *balanced* one also
balances the first-order carryover: over the rows, every condition is followed by every
other condition equally often, so that what a participant brings from one condition
into the next is spread over the comparisons instead of favouring one of them.

Williams' construction: the first row is ``0, 1, n-1, 2, n-2, 3, ...`` and row ``i`` adds
``i`` to every entry modulo ``n``. For an even ``n`` these ``n`` rows are balanced: each
ordered pair ``(a, b)``, ``a != b``, is adjacent exactly once. For an odd ``n`` no single
square of ``n`` rows can be balanced; the construction takes two squares, the rows above
and each of them reversed (``2n`` rows), and each ordered pair is then adjacent exactly
twice. Pure: no I/O.
"""

from __future__ import annotations

import itertools


def williams_rows(n: int) -> list[list[int]]:
    """The rows of a balanced Latin square of ``n`` conditions (indices 0..n-1): ``n``
    rows for an even ``n``, ``2n`` (two squares, the second the first's rows reversed)
    for an odd one.

    Raises
    ------
    ValueError
        For ``n < 1``.
    """
    if n < 1:
        raise ValueError(f"a Latin square needs at least 1 condition, not {n}")
    first = [0]
    low, high = 1, n - 1
    while len(first) < n:  # 0, 1, n-1, 2, n-2, ...
        first.append(low)
        low += 1
        if len(first) < n:
            first.append(high)
            high -= 1
    rows = [[(c + i) % n for c in first] for i in range(n)]
    if n % 2 == 1 and n > 1:
        rows += [list(reversed(r)) for r in rows]
    return rows


def construction(n: int) -> str:
    """One sentence on how the square of ``n`` conditions was made (for the plan file)."""
    if n == 1:
        return "one condition: nothing to counterbalance"
    if n % 2 == 0:
        return (f"balanced Latin square (Williams 1949), {n} conditions (even): one square of {n} "
                "sequences; each condition once in every position, each ordered pair of conditions "
                "adjacent once")
    return (f"balanced Latin square (Williams 1949), {n} conditions (odd): two squares, the second "
            f"the first's sequences reversed, {2 * n} sequences; each condition twice in every "
            "position, each ordered pair of conditions adjacent twice")


def carryover_counts(rows: list[list[int]]) -> dict[tuple[int, int], int]:
    """How often each ordered pair ``(a, b)`` is adjacent (``a`` right before ``b``)."""
    out: dict[tuple[int, int], int] = {}
    for r in rows:
        for a, b in itertools.pairwise(r):
            out[(a, b)] = out.get((a, b), 0) + 1
    return out
