"""aerobench scenes package."""
