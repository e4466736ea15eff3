"""Run outputs: track files, summaries and plots."""
