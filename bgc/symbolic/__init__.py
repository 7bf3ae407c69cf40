"""What the compile stages share and none of them owns: graph algorithms on equations and
elements (``algorithms``), symbolic forward mode through sorted assignments
(``forward_mode``) and the linear blocks solved at run time (``linear``: ``LinearBlock``,
``Regularized``), which the equations build, a constraint method declares and the kernels
solve. It imports no stage (``tests/test_layers.py``)."""
