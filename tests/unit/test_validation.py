"""The validation table's plumbing: every row names tests that exist and call check() for it."""

import re

import pytest

from tests import validation


@pytest.mark.parametrize("key", list(validation.ROWS))
def test_each_row_is_measured_by_the_tests_it_names(key):
    for node in validation.ROWS[key].tests:
        path, name = node.split("::")
        source = (validation.ROOT / path).read_text()
        body = re.search(rf"^def {name}\(.*?(?=^def |\Z)", source, re.S | re.M)
        assert body, f"{node}: no such test"
        assert re.search(rf'validation\.check\(\s*"{key}"', body.group(0)), f"{node} does not check {key!r}"


def test_check_records_and_fails_above_the_tolerance():
    row = validation.ROWS["drag"]
    validation.check("drag", row.tolerance / 2)
    assert validation._measured["drag"][-1] == row.tolerance / 2
    with pytest.raises(AssertionError, match=r"drag: measured 0.02, expected at most 0.01"):
        validation.check("drag", 0.02)


def test_table_figures_and_readme_markers(tmp_path):
    assert [validation._figure(v, "m") for v in (0.39, 1e-4, 7.6e-5, 0.0)] == ["0.39 m", "1e-4 m", "7.6e-5 m", "0 m"]
    text = validation.table({"drag": [2e-5, 3e-5]})
    assert "| 0.01 | 3e-5 |" in text and "not run" in text
    assert r"\|v_rel\|" in text  # a | in a cell does not split it
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n{validation.README_START}\nold\n{validation.README_END}\nafter\n")
    validation.write_readme("new table", readme)
    assert readme.read_text() == f"# x\n{validation.README_START}\nnew table\n{validation.README_END}\nafter\n"
    readme.write_text("no markers")
    with pytest.raises(SystemExit, match="markers"):
        validation.write_readme("t", readme)
