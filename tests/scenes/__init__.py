"""Tests of scenes: specs, world, motion, rendering, ground truth, sensor, sequence folders, cache."""
