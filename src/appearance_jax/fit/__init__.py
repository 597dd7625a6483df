"""Fitting: measurement tables in, parameters with uncertainties and plots out (DESIGN.md, Fitting)."""
