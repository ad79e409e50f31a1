"""aerobench reports package."""
