"""Studies that run solvers themselves: the stability sweep, the error split, the whole-path replay, what a network is worth, the benchmarks."""
