"""leaderboards (see README)."""
