"""H∞ synthesis: the problem, the Riccati (SLICOT) and LMI solvers, and the checks of a solution."""
