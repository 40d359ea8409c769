"""`gsbench publish --page F [--readme R]` writes only a page gsbench generated (its header) or a new
file, and a README with its claims markers, checking all of it before it writes anything; it never
deletes or replaces a picture beside the page that the page did not show. An empty store and the
tiny grid: no training."""
from __future__ import annotations

from pathlib import Path

import pytest
from paths import REPO_ROOT

from gsbench.cli import main
from gsbench.errors import InputError
from gsbench.reports.claims_page import GENERATED_MARK, README_BEGIN, README_END, Page, write_page

GRID = str(REPO_ROOT / "gsbench" / "grids" / "tiny-test.yaml")
NOTES = "# My notes\n\nNothing generated here.\n"
PNG = b"\x89PNG\r\n\x1a\n a user's picture"


@pytest.fixture
def store(tmp_path) -> Path:
    (tmp_path / "store").mkdir()
    return tmp_path / "store"


def _page(store: Path, page: Path, *extra: str) -> list[str]:
    return ["publish", "--page", str(page), "--from", str(store), "--grids", GRID, *extra]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    return err[0]


def test_a_users_page_and_its_pictures_are_never_touched(store, tmp_path, capsys):
    notes = tmp_path / "notes.md"
    notes.write_text(NOTES)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "dose_x.png").write_bytes(PNG)
    assert main(_page(store, notes)) == 1
    line = _one_line(capsys)
    assert f"{notes}: not a page gsbench generated" in line and "nothing was written" in line
    assert notes.read_text() == NOTES and (tmp_path / "notes" / "dose_x.png").read_bytes() == PNG


def test_a_readme_given_as_the_page_is_refused(store, tmp_path, capsys):
    readme = tmp_path / "README.md"
    text = f"# Project\n{README_BEGIN}\nold\n{README_END}\n"
    readme.write_text(text)
    assert main(_page(store, readme)) == 1
    assert "not a page gsbench generated" in _one_line(capsys) and readme.read_text() == text


def test_a_new_page_is_written_then_regenerated(store, tmp_path, capsys):
    page = tmp_path / "docs" / "claims.md"
    page.parent.mkdir()
    assert main(_page(store, page)) == 0
    assert GENERATED_MARK in page.read_text()
    page.write_text(page.read_text() + "an edit\n")
    assert main(_page(store, page)) == 0                     # its own page: regenerated
    assert "an edit" not in page.read_text()


def test_a_readme_without_markers_fails_before_the_page_is_written(store, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text("# Project without the claims block\n")
    page = tmp_path / "claims.md"
    assert main(_page(store, page, "--readme", str(readme))) == 1
    line = _one_line(capsys)
    assert f"{readme}: no {README_BEGIN}" in line and "nothing was written" in line
    assert not page.exists() and readme.read_text() == "# Project without the claims block\n"


def _generated(figures: list[str]) -> str:
    return "\n".join([f"{GENERATED_MARK} docs/claims.md` -->", ""] + [f"![{n}](claims/{n})" for n in figures]) + "\n"


def test_only_figures_the_old_page_showed_are_removed(tmp_path):
    page = tmp_path / "claims.md"
    folder = tmp_path / "claims"
    folder.mkdir()
    page.write_text(_generated(["dose_old.png", "dose_kept.png"]))
    for name in ("dose_old.png", "dose_kept.png"):
        (folder / name).write_bytes(b"old figure")
    (folder / "dose_mine.png").write_bytes(PNG)                # a user's, in the figures' own pattern
    new = Page(_generated(["dose_kept.png", "dose_new.png"]), "", {"dose_kept.png": b"k", "dose_new.png": b"n"})
    write_page(new, page)
    assert sorted(p.name for p in folder.iterdir()) == ["dose_kept.png", "dose_mine.png", "dose_new.png"]
    assert (folder / "dose_mine.png").read_bytes() == PNG and (folder / "dose_new.png").read_bytes() == b"n"


def test_a_figure_that_would_replace_a_users_picture_is_refused_before_writing(tmp_path):
    page = tmp_path / "claims.md"
    page.write_text(_generated([]))
    (tmp_path / "claims").mkdir()
    (tmp_path / "claims" / "dose_a.png").write_bytes(PNG)     # not shown by the page: not gsbench's
    new = Page(_generated(["dose_a.png"]), "", {"dose_a.png": b"generated"})
    with pytest.raises(InputError, match="dose_a.png: a picture the page .* does not show"):
        write_page(new, page)
    assert (tmp_path / "claims" / "dose_a.png").read_bytes() == PNG and page.read_text() == _generated([])


def test_a_page_that_is_a_link_is_refused(store, tmp_path, capsys):
    target = tmp_path / "elsewhere.md"
    target.write_text(NOTES)
    (tmp_path / "claims.md").symlink_to(target)
    assert main(_page(store, tmp_path / "claims.md")) == 1
    assert "a symbolic link" in _one_line(capsys) and target.read_text() == NOTES
