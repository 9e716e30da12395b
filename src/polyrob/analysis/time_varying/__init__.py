"""Certificates for time-varying parameters: quadratic stability and performance on a PLDI's vertices, the constant-D small gain."""
