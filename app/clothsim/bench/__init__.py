"""Benchmarks: speed, render, accuracy, stability, scaling."""
