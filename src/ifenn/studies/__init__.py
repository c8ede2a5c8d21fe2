"""What the workflow measures and draws, by job:

- ``drivers``: the studies that run solvers themselves (the stability sweep's cells, the error split's
  replay, the whole-path replay, what a network is worth, the phase-field and whole-run benchmarks);
- ``tables``: metrics and the tables read from finished runs (accuracy, speed against accuracy,
  finer references, adaptive resolution, the specimens, the summary of the numbers the docs quote);
- ``figures``: every figure (the paper's and the workflow's own).

The workflow's own bookkeeping (what a DAG spent per stage) is :mod:`ifenn.tooling`.
"""
