"""Reviewing runs: efficiency figures, segments, comparisons (docs/review.md)."""
