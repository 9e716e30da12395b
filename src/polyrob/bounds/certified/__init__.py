"""Guaranteed (interval-arithmetic) enclosures of the Jacobians: ball arithmetic, Taylor models, branch and bound."""
