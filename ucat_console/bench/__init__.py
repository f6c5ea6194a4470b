"""Benchmarks behind ``ucat-console bench`` (figures for the README, never test assertions)."""
