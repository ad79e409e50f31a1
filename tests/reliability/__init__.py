"""Reliability tests: bad inputs, determinism, faults (kill -9, lost workers), properties."""
