"""The scorer version: recorded in every scores.json (``toolkit.scorer_version``).

Bump it with every intended change to what the metrics compute (sampling, matching, filtering, a
default of :class:`rsart.evaluation.score.EvalConfig`), regenerate the pinned reference scores
(``python tests/data/reference/regenerate.py``) and add an entry to CHANGELOG.md's metrics section that
says what moved and by how much on the reference set. tests/rsart/evaluation/test_reference_scores.py
fails until all three agree. The leaderboard never ranks rows of different scorer versions together.
"""
SCORER_VERSION = "2"
