"""Benchmarks: speed, render, accuracy, stability, scaling, and the rest `clothsim bench` lists."""
