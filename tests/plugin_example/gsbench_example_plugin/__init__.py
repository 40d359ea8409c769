"""An example gsbench plugin: one method (method.py) and its spec beside it (spec.py)."""
