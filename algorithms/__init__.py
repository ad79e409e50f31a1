"""aerobench algorithms package."""
