"""The structured singular value: block structures, frequency responses, upper and lower bounds, the check between grid points."""
