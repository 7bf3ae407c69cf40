"""``bgc sweep``: a model's metrics over a grid or a Latin hypercube of its parameters, run
in parallel on a Dask cluster.

Three stages, one structure between each pair:

- ``plan``: the ``-p NAME=START:STOP[:COUNT]`` axes -> ``Plan`` (the points, one row of
  parameter values each): a grid, or a Latin hypercube (``--samples``);
- ``runner``: ``Job`` (the compiled module, the base parameters, the metrics) and the Plan
  -> ``Point`` per row, computed on the workers (``metrics.evaluate``): the module reaches
  each worker once (a worker plugin), each task carries one row of values;
- ``write``: the Points -> CSV (and Parquet if pyarrow is importable) and one PNG per
  metric against each parameter.
"""
