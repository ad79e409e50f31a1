"""Tests of algorithms: known motion recovered, bad input refused, invariants."""
