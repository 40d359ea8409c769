"""`example_l1`: vanilla 3DGS whose photometric loss is L1 alone by default (its own config section
sets the D-SSIM weight). The training recipe is the shared one; the method only names itself."""
from __future__ import annotations

from gsbench.methods.vanilla import Vanilla


class ExampleL1(Vanilla):
    name = "example_l1"
