"""baselines_adapters (see README)."""
