"""ngspice: running it, validating against it, benchmarking beside it."""
