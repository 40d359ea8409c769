"""What the report knows about metrics and studies: display names, units, which direction is
better, how many decimals. One place, so tables, plots and the HTML agree.

The metrics and their display specs are gsbench/metric_table.py; the studies methods/gaussiands/study_table.py.
"""
from __future__ import annotations

from gsbench.method_table import METHODS, get_spec
from gsbench.metric_table import LOGICAL_SPEC, METRICS, MetricSpec

from gsbench.methods.gaussiands.study_table import (AX_FORMULATION, AX_LAMBDAS, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY,  # noqa: F401  isort: skip
                             AX_NOISE_TYPE, AX_ORDERING, AX_VIEWS)
from gsbench.methods.gaussiands.study_table import STUDIES as STUDY_TABLE

# Logical metric -> concrete metric name per protocol ("mIoU" of a 3D-OVS scene is miou_3dovs).
LOGICAL = {
    "miou": {"3dovs": "miou_3dovs", "lerf": "miou_lerf"},
    "mbiou": {"3dovs": "mbiou_3dovs"},
}

PROTOCOL_LABELS = {"3dovs": "3D-OVS protocol", "lerf": "LERF-OVS protocol", None: "no semantic protocol"}

# the paper's studies' labels (methods/gaussiands/study_table.py); control and smoke studies are reported elsewhere
STUDIES = {name: st.label for name, st in STUDY_TABLE.items() if st.kind == "paper"}


ORDERING_LABELS = {"random": "Random", "filename": "Filename order", "pose": "Pose-nearest"}
ORDERING_ORDER = ["random", "filename", "pose"]
FORMULATION_LABELS = {
    "none": "No depth loss", "raw_l1": "Raw L1 supervision", "minmax": "Min-max normalized depth",
    "scale_shift": "Scale-shift aligned depth", "pearson": "Pearson correlation",
}
FORMULATION_ORDER = ["none", "raw_l1", "minmax", "scale_shift", "pearson"]
NOISE_LABELS = {"gaussian": "Gaussian", "poisson": "Poisson", "motion_blur": "Motion blur",
                "salt_pepper": "Salt-and-pepper"}
NOISE_ORDER = ["gaussian", "poisson", "motion_blur", "salt_pepper"]
# Paper order of the loss subsets (depth, tv, ds); the paper omits (tv, ds), listed here before "all".
LOSS_SUBSET_ORDER = [
    (False, False, False), (True, False, False), (False, True, False), (False, False, True),
    (True, True, False), (True, False, True), (False, True, True), (True, True, True),
]

# The reference row of each study (methods/gaussiands/study_table.py): every other row is compared with it
# (difference and its 95 % interval); a study without one has no reference.
STUDY_REFERENCE: dict[str, dict] = {n: st.reference_columns() for n, st in STUDY_TABLE.items() if st.reference}
REFERENCE_TEXT = {n: st.reference_text for n, st in STUDY_TABLE.items() if st.reference}


def method_label(method: str) -> str:
    """The registered method's report label (gsbench.method_table); an unknown name as it is."""
    return get_spec(method).label if method in METHODS else str(method)


def metric_spec(name: str) -> MetricSpec:
    """Spec of a metric; unknown metrics get a neutral spec (no best marked)."""
    if name in METRICS:
        return METRICS[name]
    if name in LOGICAL_SPEC:
        return LOGICAL_SPEC[name]
    return MetricSpec(name, name.replace("_", "\\_"), None, 1.0, 3)
