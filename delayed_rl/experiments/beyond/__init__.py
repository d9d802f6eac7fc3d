"""Experiments beyond the thesis (its future work), one module each, on the same framework."""
