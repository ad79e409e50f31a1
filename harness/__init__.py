"""aerobench harness package."""
