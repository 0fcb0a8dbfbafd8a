"""The benchmarks behind ``deltoctl bench``: each measures and returns its figures."""
