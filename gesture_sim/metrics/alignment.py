"""Levenshtein alignment of two token sequences (words, phone labels) with its back-trace:
the word error rate of a recogniser and the phone error rate of a phone source
(``tools/live_words_eval.py``, ``tools/phone_sources.py``)."""

from __future__ import annotations

import numpy as np


def edit_ops(ref: list[str], hyp: list[str]) -> tuple[int, list[tuple[int, int]]]:
    """Levenshtein distance (substitutions, deletions, insertions) of two token sequences and
    the pairs (i, j) of matched (equal) tokens on one best path."""
    n, m = len(ref), len(hyp)
    d = np.zeros((n + 1, m + 1), dtype=np.int32)
    d[:, 0] = np.arange(n + 1)
    d[0, :] = np.arange(m + 1)
    for i in range(1, n + 1):
        sub = d[i - 1, :-1] + (np.asarray(hyp) != ref[i - 1])
        row = np.minimum(d[i - 1, 1:] + 1, sub)
        # insertions along the row (sequential dependency)
        out = np.empty(m + 1, dtype=np.int32)
        out[0] = i
        for j in range(1, m + 1):
            out[j] = min(row[j - 1], out[j - 1] + 1)
        d[i] = out
    pairs: list[tuple[int, int]] = []
    i, j = n, m
    while i > 0 and j > 0:
        if d[i, j] == d[i - 1, j - 1] + (ref[i - 1] != hyp[j - 1]):
            if ref[i - 1] == hyp[j - 1]:
                pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
        elif d[i, j] == d[i - 1, j] + 1:
            i -= 1
        else:
            j -= 1
    return int(d[n, m]), pairs[::-1]
