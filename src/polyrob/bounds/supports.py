"""Support values of the Jacobian cloud along given directions: the search behind the PLDI's bounds.

:func:`support_values` runs, for every direction, the design, the uniform
screens, the local searches (:mod:`polyrob.bounds.local_search`) and the
verification rounds that :func:`polyrob.bounds.pldi.bound_pldi` describes.
"""

from __future__ import annotations

import time

import numpy as np

from polyrob.bounds import local_search, screens, search
from polyrob.bounds.options import SearchEffort

__all__ = ["support_values"]


def support_values(problem, q, directions, index, dropped, pool, progress, effort: SearchEffort):
    """Support values (and witnesses) along every direction: design, screens, local search, verification.

    ``effort`` has its defaults sized (:meth:`SearchEffort.sized`).
    """
    samples, screen, screen_starts, seed = effort.samples, effort.screen, effort.screen_starts, effort.seed
    starts_per_direction = effort.starts_per_direction
    k = len(index)
    m = problem.m
    t0 = time.perf_counter()
    stages = {}
    if k:
        # a dense uniform screen of the whole domain adds start positions
        # near narrow peaks that the position design straddles
        extra = screens.screen(problem, directions, index, screen, screen_starts, seed, pool) if screen else None
        stages["screen"] = time.perf_counter() - t0
        values, starts, depends = search.support_pass(
            problem, q, directions, index, progress, pool, starts_per_direction, extra
        )
        stages["design"] = time.perf_counter() - t0 - stages["screen"]
    else:
        values, starts, depends = np.zeros(0), np.zeros((0, 1, 3 * m)), np.zeros((0, 2 * m), bool)
    witnesses = starts[:, 0].copy()
    t_sample = time.perf_counter() - t0
    sampled_width = values[:k] + values[k : 2 * k]
    rounds = 0
    if effort.refine and k:
        args = (index, dropped, depends, progress, pool)
        t1 = time.perf_counter()
        values, witnesses = local_search.refine(
            problem, directions, values, starts, index, dropped, progress, pool, depends
        )
        stages["refine"] = time.perf_counter() - t1
        values, witnesses = local_search.cross_seed(problem, directions, values, witnesses, *args)
        stages["cross_seed"] = time.perf_counter() - t1 - stages["refine"]
        t1 = time.perf_counter()
        if screen:
            # a second screen, around the witnesses of every direction
            near = screens.screen(problem, directions, index, screen, screen_starts, seed + 1, pool, witnesses)
            starts, _ = search.exact_witnesses(problem, near, directions, index, pool)
            starts = np.concatenate([witnesses[:, None], starts], axis=1)
            values, witnesses = local_search.refine(
                problem, directions, values, starts, index, dropped, progress, pool, depends
            )
            values, witnesses = local_search.cross_seed(problem, directions, values, witnesses, *args)
        stages["screen_near_witnesses"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        # Verification rounds: a fresh design (another scramble) must not beat
        # any support value; where it does, refine again from its witness.
        for rounds in range(1, effort.verify_rounds + 1):
            q_new = search.position_design(problem, samples, dropped, seed + 7919 * rounds)
            # only what beats a support value is wanted: positions whose cheap bound cannot are skipped
            # (their bound stands in for the landscape of a beaten direction, below its support value)
            v_new, _ = search.inner_maxima(problem, q_new, directions, index, progress, pool, floor=values)
            beaten = np.flatnonzero(v_new.max(axis=0) > values + 1e-9 * (1.0 + np.abs(values)))
            if not beaten.size:
                break
            peaks = q_new[search.landscape_peaks(problem, q_new, v_new[:, beaten], starts_per_direction)]
            s_new, v_start = search.exact_witnesses(problem, peaks, directions[beaten], index, pool)
            v_ref, w_ref = local_search.refine(
                problem,
                directions[beaten],
                v_start[:, 0],
                s_new,
                index,
                dropped,
                progress,
                pool,
                depends[beaten],
            )
            values[beaten], witnesses[beaten] = v_ref, w_ref
            values, witnesses = local_search.cross_seed(problem, directions, values, witnesses, *args)
        stages["verification"] = time.perf_counter() - t1
    t_refine = time.perf_counter() - t0 - t_sample
    return values, witnesses, sampled_width, stages, rounds, t_sample, t_refine
