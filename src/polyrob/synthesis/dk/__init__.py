"""Full-order D-K / D-G-K iteration: the loop, its strategies (μ bound, fit, H∞ step), the frequency grid, the μ sweep."""
