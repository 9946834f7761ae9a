"""Benchmarks reproducing the PCC paper."""
