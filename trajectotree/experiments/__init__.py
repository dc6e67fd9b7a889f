"""Experiments: sweeps of trials (plan, save, simulate), their executions and the paper's report."""
