"""Benchmarks behind ``ucat-console bench`` (figures for docs/performance.md, never test assertions)."""
