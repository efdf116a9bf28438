"""Benchmarks and the simulated robot that drives the service over HTTP."""
