"""GaussianDS, the reference method: the method itself (method.py), its spec (spec.py: registration,
resolver, budget) and the studies it is measured in, with the paper's numbers and the positive controls
(study_table.py, its shapes in study_types.py). Importing the package imports none of them."""
