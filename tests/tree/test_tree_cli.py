"""Tree command line: bad input -> one line naming body and field, exit 2, nothing written."""

from __future__ import annotations

import pytest
import tomli_w
from tree_documents import boom_document

from oos_drake.multibody.tree_cli import main


def _write(tmp_path, document):
    path = tmp_path / "tree.toml"
    path.write_bytes(tomli_w.dumps(document).encode())
    return path


def test_bad_tree_exits_2_and_writes_nothing(tmp_path, capsys):
    document = boom_document()
    document["control"]["controlled_body"] = "HBU"
    out = tmp_path / "sdf"
    assert main(["sdf", str(_write(tmp_path, document)), str(out)]) == 2
    err = capsys.readouterr().err
    assert err == "error: control: controlled_body 'HBU' is not a body (did you mean 'HUB'?)\n"
    assert not out.exists()


def test_cycle_exits_2(tmp_path, capsys):
    document = boom_document()
    document["bodies"][0]["parent"] = "BOOM"
    document["bodies"][0]["joint"] = {"type": "fixed"}
    assert main(["check", str(_write(tmp_path, document))]) == 2
    assert capsys.readouterr().err.startswith("error: HUB: parent: the tree has a cycle")


@pytest.mark.drake
def test_sdf_written_for_a_valid_tree(tmp_path):
    pytest.importorskip("pydrake")
    out = tmp_path / "sdf"
    assert main(["sdf", str(_write(tmp_path, boom_document())), str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "appendage_PANEL.sdf", "appendage_SKEWED.sdf", "spacecraft.sdf"
    ]  # fmt: skip
