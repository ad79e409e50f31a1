"""Tests of reports: loading a run, tables, plots, pictures, the HTML and Markdown reports."""
