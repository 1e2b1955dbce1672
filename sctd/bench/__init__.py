"""Benchmarks: the programs behind ``sctd bench ...``.

They sit on top of every other layer (application code, with the CLI): each one
starts processes or simulations, measures, and prints figures. The test suite never
asserts wall-clock times; these commands are where speed is shown.
"""
