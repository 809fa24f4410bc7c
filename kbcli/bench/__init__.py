"""Benchmarks behind ``kbcli bench ...``: simulations that print tables (not tests)."""
