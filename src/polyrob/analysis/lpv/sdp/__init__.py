"""A structured interior-point solver for the bounded-real LMIs of :func:`polyrob.lpvnorm` on a grid.

:mod:`~polyrob.analysis.lpv.sdp.family` writes the LMIs' operators and
Schur complement from the grid's ``A, B, C, D`` (no coefficient matrix);
:mod:`~polyrob.analysis.lpv.sdp.interior` runs the primal-dual method on it.
``lpvnorm(..., solver="structured")`` uses them.
"""
