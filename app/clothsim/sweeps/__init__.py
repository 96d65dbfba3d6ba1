"""Parameter sweeps (``clothsim sweep``, :func:`clothsim.sweep`): contact sheets and datasets.

The package is ``sweeps`` so that ``clothsim.sweep`` stays the function.
"""
