"""Tests of appearance_jax.soapfilm (Huang 2022, Ch. 3)."""
