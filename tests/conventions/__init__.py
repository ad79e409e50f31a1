"""Tests of the conventions every package shares: flow layout and signs, file formats."""
