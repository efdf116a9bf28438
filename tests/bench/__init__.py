"""Tests of the benchmarks' summary (no benchmark is run)."""
