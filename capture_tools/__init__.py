"""capture_tools (see README)."""
