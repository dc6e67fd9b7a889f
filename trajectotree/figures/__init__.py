"""Figures: one plan's or one run's drawings, and a sweep's statistics plots."""
