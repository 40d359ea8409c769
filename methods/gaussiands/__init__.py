"""GaussianDS, the reference method: the method itself (method.py), its spec (spec.py: registration,
resolver, budget) and the paper's numbers it is compared with (paper.py). Importing the package
imports none of them."""
