"""Figures (matplotlib, Agg backend): functions that take artifacts' arrays and save a PNG."""

import matplotlib

matplotlib.use("Agg")
