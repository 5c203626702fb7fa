"""Experiment runners (application layer: they may import ``drivers`` and ``fusion``)."""
