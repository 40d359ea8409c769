"""The one-home tables: every metric a results.json may hold has its display spec, and every shipped
grid's study is in the studies table with the axes it varies."""
from __future__ import annotations

from gsbench.grids.grid_file import GRID_DIR, load_grid
from gsbench.methods.gaussiands.study_table import MAIN_STUDIES, STUDIES
from gsbench.metric_table import KNOWN_METRICS, METRICS
from gsbench.reports.display import STUDIES as REPORT_LABELS
from gsbench.reports.display import STUDY_REFERENCE, metric_spec


def test_every_known_metric_has_its_spec_and_the_report_reads_the_same_one():
    assert set(METRICS) >= set(KNOWN_METRICS)
    for name in KNOWN_METRICS:
        assert metric_spec(name) is METRICS[name]
    assert METRICS["miou_lerf_decode_heldout"].label == "mIoU (%)".replace(" (%)", " decode held-out (%)")


def test_every_shipped_grid_names_a_study_of_the_table_and_varies_only_its_axes():
    for path in sorted(GRID_DIR.glob("*.yaml")):
        g = load_grid(path.stem)
        assert g.study in STUDIES, path.name
        assert set(g.axis_keys) <= set(STUDIES[g.study].axes), path.name


def test_the_report_takes_labels_references_and_main_studies_from_the_table():
    assert set(REPORT_LABELS) == {n for n, s in STUDIES.items() if s.kind == "paper"}
    assert STUDY_REFERENCE["ordering"] == {"axis.priors.ordering": "pose"}
    assert STUDY_REFERENCE["reconstruction"] == {"method": "gaussiands"}
    assert MAIN_STUDIES == (None, "reconstruction")
