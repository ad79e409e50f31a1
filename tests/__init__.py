"""The aerobench test suite: one package per project package (names cannot clash across folders)."""
