"""Tests of harness: suites, runner, metrics, results, gate, CLI."""
